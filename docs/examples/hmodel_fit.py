"""The H-model fitted to a drained biaxial curve (docs/fit.md): here a curve made by the model
itself with phi_g = 25 deg, so the fit must find 25 again. SI units, compression positive.
docs/api.md.
"""
from hmodel import HParams
from point.experiment import biaxial_test
from hmodel.fit import fit_curve, format_result, make_curve

# the "measured" curve: eps1, q [Pa], eps_v at 200 kPa (read_curve(path) reads one from a CSV)
true = HParams(phi_g=25.0, n_dir=36)
r = biaxial_test(true, 200e3, d_eps1=1e-4, eps1_max=0.03)
p, q, eta = r.invariants()
curve = make_curve(r.eps[:, 0], q, eps_v=r.eps[:, 0] + r.eps[:, 1], sigma2=200e3,
                   source="the model's own curve, phi_g = 25 deg")

# fit phi_g from a start of 20 deg (Table I), the other parameters held
res = fit_curve(curve, HParams(n_dir=36), free=("phi_g",), n_starts=2, d_eps1=1e-4,
                d_eps1_search=1e-4)
print(res.status, f"phi_g = {res.params.phi_g:.3f} deg")
print(format_result(res, curve))
