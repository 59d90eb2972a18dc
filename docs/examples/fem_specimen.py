"""The plane-strain FE specimen (scikit-fem) with the H-model at every quadrature point: the
drained biaxial test past the peak with the global (det K, K_s) and local checks at every step,
then the burst experiment in dynamics. A coarse, fast version of `python -m fem biaxial` and
`python -m fem burst` (10 x 20 quads, 180 orientations). docs/api.md.
"""
from fem.biaxial import BiaxialConfig, run_biaxial
from fem.burst import BurstConfig, run_burst

cfg = BiaxialConfig(nx=2, ny=4, n_dir=36, eps1_max=0.03, d_eps1=5e-4, sigma2=200e3,
                    fields=False)                 # width 0.05 m, height 0.1 m, Table I material
res = run_biaxial(cfg)                            # out_dir="DIR" also writes curve.csv, ...
c = res.curve                                     # one array per column of curve.csv, one row a step
print(f"{len(c['step']) - 1} steps to eps1 = {100 * c['eps1'][-1]:.2f} %, "
      f"peak q = {c['q'].max() / 1e3:.1f} kPa")
for name, e in res.summary["events"].items():     # the first firing of every criterion
    where = (f"eps1 = {100 * e['eps1']:.2f} %, eta = {e['eta']:.4f}" if e["row"] is not None
             else "not reached")
    print(f"{e['label']}: {where}")

# the burst experiment on the same specimen, in dynamics (docs/burst.md): R = -2 from 0.9 of the
# material point's drained peak, G held at G_switch + B dc just below and just past the c peak
burst = run_burst(BurstConfig(specimen=cfg, ratios=(-2.0,), start_fractions=(0.9,), fields=False))
for row in burst.rows:                            # the columns of burst.csv
    print(f"burst R = {row['ratio']:g}, {row['switch']}: {row['outcome']} (c peak at eta = "
          f"{row['eta_peak_c']:.4f}, E_c - E_c(0) at most {row['ke_w2ext_max']:.3g} x W2_ext)")
