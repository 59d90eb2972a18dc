"""The burst experiment of the material point (docs/burst.md): the proportional strain path
d eps2 = R d eps1 from 0.9 of the drained peak, c = s1 + R s2 held just below and just past its
peak. Table I, 200 kPa, the default homogeneous specimen. docs/api.md.
"""
from hmodel import HParams
from point.burst import Dynamics, Specimen, run_burst

P = HParams()
res = run_burst(P, ratios=[-2.0], start_fractions=[0.9], dc=20.0,      # dc [Pa]: the held step
                specimen=Specimen(width=0.05, height=0.1, density=1600.0), dynamics=Dynamics())
print(f"drained peak eta = {res.eta_peak:.4f}")
for row in res.rows:             # one per switch: the columns of burst.csv
    print(f"R = {row['ratio']:g}, start {row['start_fraction']:g}, {row['switch']}: c peak at "
          f"eta = {row['eta_peak_c']:.4f}; held at c_switch + {row['dc']:g} Pa: {row['outcome']} "
          f"(E_c - E_c(0) at most {row['ke_w2ext_max']:.3g} x W2_ext, "
          + (f"past 2 x W2_ext at {row['t_release_t1']:.2f} T1" if row["released"] else "never 2 x")
          + f"; energy check {row['energy_check']:.1e})")
h = res.histories[-1]            # time series of the last run: t [s], ke [J/m], eps1, c [Pa], ...
print(f"{h['switch']} run: {len(h['t'])} time steps to t = {1e3 * h['t'][-1]:.1f} ms")
