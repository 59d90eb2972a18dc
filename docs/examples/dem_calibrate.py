"""The calibration of the DEM against the H-model's drained biaxial test (docs/dem.md): the
four target figures of a curve, the global search on a cheap analytic stand-in, and a real
calibration of kn_over_d alone on a 100-disk sample (seconds, not the 20 min of the default
2000-disk one). SI units, compression positive. Files go to out/api_calibrate/. docs/api.md.
"""
import math

from dem import calibrate as C
from dem.params import DemParams

# the targets: the H-model's curve (Table I, 200 kPa) read as the DEM's curves are
h = C.hmodel_curve(200e3)
target = C.curve_figures(h["eps1"], h["q"], smooth=0.0, eps_v=h["eps_v"])
print(f"H-model: peak q {target['peak_q'] / 1e3:.1f} kPa, 95 % of it first at eps1 = "
      f"{100 * target['eps1_95']:.3f} %, secant {target['secant'] / 1e6:.1f} MPa, dilatancy "
      f"ratio {target['dilatancy']:.3f}")

# the search alone, on figures that are analytic functions of the parameters (u in [0, 1]^2)
space = C.make_space(("kn_over_d", "phi_g"), DemParams())


def evaluate(points, stage):
    out = []
    for v in points:
        u = space.u_of(v)
        fig = {"peak_q": target["peak_q"] * (1 + 0.3 * (u[1] - 0.4)),
               "eps1_95": target["eps1_95"] * math.exp(-1.5 * (u[0] - 0.6)),
               "secant": target["secant"] * math.exp(1.2 * (u[0] - 0.6)),
               "dilatancy": target["dilatancy"] * (1 + 0.1 * (u[1] - 0.4))}
        rec = C.compare(fig, target)                       # errors, met flags, score
        rec.update(fig, index=len(out), values=list(v))
        out.append(rec)
    return out


best, seen, trace, why, info = C.surrogate_search(space, evaluate, target, initial=8,
                                                  max_evals=30)
print(f"analytic search: {why} after {len(seen)} sets: kn_over_d = {best['values'][0]:.4g} Pa, "
      f"friction = {best['values'][1]:.4g} deg")

# a real calibration: kn_over_d of a 100-disk sample, each set on seeds 1 and 2, checked on 3
s = C.run_calibration("out/api_calibrate", DemParams(n=100), vary=("kn_over_d",),
                      seeds=(1, 2), check_seeds=(3,), initial=3, max_evals=5, rate=0.05,
                      eps_max=0.02, post_peak_strain=0.005, workers=1, verbose=False)
print(f"calibration: {s['evaluations']} sets, stopped: {s['stopped']}; best kn_over_d = "
      f"{s['best_params']['kn_over_d']:.4g} Pa; see out/api_calibrate/report.md")
for line in s["verdict"]["text"]:
    print("  " + line)
