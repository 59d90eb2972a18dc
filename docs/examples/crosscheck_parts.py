"""The cross-check's parts as a script calls them (docs/crosscheck.md): the H-model at its point
A and the FE specimen on a coarse mesh, then the paper's section-5 conclusions in numbers (the
DEM part, ``dem_part``, is minutes at the least: ``run_crosscheck`` runs all three).
SI units, compression positive. docs/api.md.
"""
from crosscheck import conclusions, fem_part, hmodel_part
from hmodel import HParams
from point.probes import format_arcs

P = HParams(n_dir=36)              # the H-model and the FE material: Table I, 36 orientations
h = hmodel_part(params=P, domain_sigma2=())     # path, point A (eta 1.029), sweep; no domain
fem = fem_part("out/api_crosscheck/fem", nx=2, ny=4, n_dir=36, eps1_max=0.01, params=P)

c = conclusions(h, None, fem)      # no DEM rows: its conclusions are None
hm = c["hmodel"]
print(f"H-model at A: cone W2 <= 0 at {format_arcs(hm['cone_w2'])} deg, minimum W2 "
      f"{hm['min_w2']:.3f} at {hm['alpha_min_w2']:.1f} deg (third quadrant: "
      f"{hm['cone_in_third_quadrant']})")
print(f"FE specimen against the material point: max |q_FE - q_mp| / q_max = "
      f"{c['fem']['max_rel_q_diff_vs_material_point']:.1e}")
