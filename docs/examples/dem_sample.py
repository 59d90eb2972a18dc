"""The DEM sample (paper section 4): a small sample compacted and sheared (drained biaxial test,
states saved along the path), two stress probes at A, and the burst experiment from 0.9 of the
peak. 300 disks at 0.05/s instead of the paper's 12,000 at 0.01/s, so that it takes seconds;
SI units, compression positive, axis 1 = y = axial. Files go to out/api_dem/. docs/api.md.
"""
from dem import io
from dem.burst import BurstOptions, run_burst
from dem.experiment import run_biaxial
from dem.params import DemParams
from dem.probes import ProbeOptions, reference_state, run_probes

P = DemParams(n=300, seed=1)         # the paper's contact law and sample, 300 disks
bx = run_biaxial(P, "out/api_dem/biaxial", rate=0.05, eps_max=0.02, vtk=False, verbose=False)
print(f"biaxial test: {len(bx.rows)} rows, porosity after compaction "
      f"{bx.compaction['porosity']:.4f}, state A in {bx.state_a_path}")

# stress probes at A (|d sigma| = 2.5 kPa), each decided: equilibrium, failure or undecided
state_A, meta = io.load_state(bx.state_a_path)
opts = ProbeOptions()
# the probes start from A relaxed at its own wall stresses (out/api_dem/probes/stateR.npz)
ref, relaxation = reference_state(state_A, "out/api_dem/probes", opts, verbose=False)
for row in run_probes(ref, [45.0, 247.5], opts, workers=1, verbose=False):
    w2 = f"w2 = {row['w2']:.3f}" if row["outcome"] == "equilibrium" else "no W2"
    print(f"probe alpha_sigma = {row['alpha_sigma']:g} deg: {row['outcome']}, {w2}, "
          f"{'plastic' if row['plastic'] else 'elastic'}")

# the burst: R = -2 from the state saved at 0.9 of the peak eta, c held below / past its peak
rows, summary = run_burst("out/api_dem/biaxial", "out/api_dem/burst", [-2.0], [0.9],
                          BurstOptions(), workers=1, verbose=False)
for row in rows:
    print(f"burst R = {row['ratio']:g}, {row['switch']}: {row['outcome']} after {row['steps']} "
          f"steps (E_c gained at most {row['ke_w2ext_max']:.3g} x the held step's work)")
