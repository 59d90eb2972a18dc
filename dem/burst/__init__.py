"""Failure made to happen in the DEM, from rest under a dead load: the proportional strain path,
its conjugate stress held past its peak at rest, and the burst of kinetic energy (paper Eq. 1;
``docs/burst.md``, ``docs/dem.md``).

From a state of the drained biaxial path (``dem biaxial --save-fractions``), the walls impose the
proportional strain path d eps2 = R d eps1 (R < 0: lateral extension) at the axial strain rate of
the biaxial test (``walls.strain_rate``, both axes strain controlled; engineering strains on the
biaxial test's reference lengths) while the stress conjugate to it, c = s1 + R s2 (wall stresses,
compression positive), is recorded: along the path W2 = d eps1 dc, so W2 = 0 where c peaks.

* **The loaded peak** (``proportional_path``): the largest c recorded, confirmed once the path
  has gone ``peak_strain`` (0.5 %) of axial strain beyond it without a larger one, or c has
  fallen from it by ``peak_drop`` (150 kPa): the DEM's c is noisy, with stick-slip falls of up to
  62 kPa that it recovers within a few tenths of a percent (``docs/dem.md``). A path that
  unloads (its mean wall stress below ``UNLOADED`` of its start: the walls have left the grains,
  as along R = -2.5) ends without a peak and without runs. Under strain control at the test's
  rate this peak carries the loading's rate overstress: it is an upper bound of what the
  sample holds at rest.
* **The peak at rest** (``staircase``): the path's start state relaxed at fixed strain
  (``relax``: the walls still, until dem.settle's equilibrium and a c that no longer drifts),
  then G held by steps under a dead load, each hold from the previous equilibrium (so from
  rest): a step that settles moves the staircase up, one that fails is halved, down to ``dc``;
  the c peak at rest is the last c held, and the failing hold of +dc from it is the ``past``
  run. ``below``: from the first equilibrium of the staircase whose c reaches c_rest(start) +
  ``below_rise`` (c_peak_rest - c_rest(start)), held at its c + dc. The loaded peak's state is
  relaxed too (rest.csv: its c at rest and the drop from the loaded c). Relaxing the path's
  states at fixed strain and holding the largest of their c + dc was tried first: at 2000 disks
  that hold settled (docs/dem.md: a state relaxed at fixed strain keeps less c than the sample
  can hold).
* **The dead load** (``walls.dead_load``): the walls, tied, are one dynamic degree of freedom,
  the platens' shortening U1, of generalized mass m_G (``wall_mass_rule``: their period on their
  contact stiffness is ``wall_period_steps`` steps), under the constant generalized force
  G_held = G(switch) + W t dc: m_G U1'' = G_held - G, no servo, no speed limit, no damping on
  the walls; W2_ext = dG dU1 exactly. ``hold="servo"`` keeps the servo on c instead.
* **The runs** (``hold``) end by ``dem.settle``'s rule: equilibrium over a window (unbalanced
  force, the stress error |G - G_held| / (W t) (servo: |c - c_target|) <= stress_tol, strain
  drift, backbone kinetic energy); failure when the strain since the switch passes
  ``fail_strain`` or runs away (``runaway_ratio`` times the elastic strain of ``strain_norm``)
  with the stress error above ``runaway_stress`` and the kinetic energy not decaying; undecided
  at the cap.

Every check records (history.csv): total and backbone kinetic energy [J], unbalanced ratio,
strains, wall stresses, c, c_target, |c - c_target|, ``w2_ext_held`` = dG dU1 (dG = W_s t dc,
U1 = H0 eps1 the platens' shortening: what the held step puts in if G were held exactly), the
walls' own secant second-order work sum_w dF_w dU_w, ``w2_int_secant``, the paper's contact sum
sum_c df . dl over the grain and wall contacts since the switch (Eq. 15 form, secant; by Eq. 14
it is the walls' less sum_p dF_p . dx_p), and the energy ledger from the switch (``dem.ledger``):
the walls' work, the contact work and its split into stored and dissipated energy, the Cundall
damping's work, and Eq. 1 in second-order form, E_c - E_c(0) = W2_ext - W2_int + W_damp + U0,
closed to round-off (``w2_ext``, ``w2_int``, ``u0``, ``eq1_bookkeeping``).

Modules: ``options`` (``BurstOptions`` and the peak rule), ``runs`` (the path, the relaxation at
fixed strain, the kinematic probe of the path, the held run), ``stairs`` (the staircase: the c
peak at rest, the below and past runs; its runs go to ``dem.pool``, in this process or over
workers: the probes beside the staircase), ``journal`` (a staircase's journal and the
command's checkpoint), ``theory`` (k_path's noise and the theory's verdict), ``report`` (the rows
and files), ``figures``, ``command`` (``check_sample_size``, ``load_starts``, ``run_burst``,
``burst_job``: its runs as generators for one pool with other work).
"""
from .options import BurstOptions, HOLDS, SWITCHES, below_row, confirm_peak, scan_peak
from .runs import (H, HISTORY_COLUMNS, HOLD_ANATOMY_COLUMNS, HOLD_LEDGER_COLUMNS, HoldResult, ONSET,
                   PATH_COLUMNS, PATH_LEDGER_COLUMNS, PathResult, ProbeResult, RelaxResult,
                   UNLOADED, growth, hold, ke_growth, path_probe, probe_rate_of, proportional_path,
                   relax, wall_mass_rule, wall_work)
from .theory import (AVALANCHE, CLEARLY, Noise, k_noise, staircase_verdict, theory_verdict,
                     verdict_of_folder)
from .journal import checkpoint_header, read_checkpoint
from .stairs import StairResult, staircase
from .figures import OUTCOME_COLOR, plot_burst, plot_k_path
from .report import (BURST_COLUMNS, PROBE_COLUMNS, REST_COLUMNS, STAIR_COLUMNS, burst_row,
                     write_burst_files)
# check_ratio: dem.__main__'s --ratios
from .command import burst_job, check_ratio, check_sample_size, load_starts, run_burst

__all__ = ["AVALANCHE", "below_row", "BURST_COLUMNS", "burst_row", "BurstOptions", "check_ratio",
           "check_sample_size", "checkpoint_header", "CLEARLY", "confirm_peak", "growth", "H", "HISTORY_COLUMNS",
           "hold", "HOLD_ANATOMY_COLUMNS", "HOLD_LEDGER_COLUMNS", "HoldResult", "HOLDS", "k_noise",
           "Noise",
           "ke_growth", "load_starts", "ONSET", "OUTCOME_COLOR", "PATH_COLUMNS",
           "PATH_LEDGER_COLUMNS", "path_probe", "PathResult", "plot_burst", "plot_k_path",
           "PROBE_COLUMNS", "probe_rate_of", "ProbeResult", "proportional_path", "read_checkpoint",
           "relax", "RelaxResult", "REST_COLUMNS", "run_burst", "burst_job", "scan_peak",
           "STAIR_COLUMNS",
           "staircase", "staircase_verdict", "StairResult", "SWITCHES", "theory_verdict", "UNLOADED",
           "verdict_of_folder", "wall_mass_rule", "wall_work", "write_burst_files"]
