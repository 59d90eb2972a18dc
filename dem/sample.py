"""Seeded sample generation and isotropic compaction (paper section 4).

The generator places N disks with radii uniform in [r_min, r_max] (numpy default_rng(seed))
row by row in a loose square box; `compact` shrinks that sample, grows the radii back in
place (so that the geometric porosity would be the target) while the four walls are
servo-controlled at the target isotropic stress, with friction switched off or reduced (so the packing gets
dense, the paper reaches porosity 0.16 at 200 kPa), restores the friction at the
confined state and re-equilibrates.  The porosity reached is reported, not imposed.
"""
from __future__ import annotations

import math
import sys
from typing import NamedTuple

import numpy as np

from .params import DemParams
from .regime import check_regime
from .simulation import Simulation, solid_fraction
from . import walls as W


def generate(params: DemParams):
    """Loose seeded sample.  Returns (x (N,2) [m], r (N,) [m], walls (4,) [m])."""
    rng = np.random.default_rng(params.seed)
    n = params.n
    r = rng.uniform(params.r_min, params.r_max, n)
    # row width chosen so the loose box is roughly square
    area = np.sum((2 * r) * 2 * params.r_max)
    width = math.sqrt(area)
    gap = 0.05 * params.r_min
    x = np.empty((n, 2))
    cx = gap
    row = 0
    h = 2 * params.r_max + gap
    for i in range(n):
        d = 2 * r[i] + gap
        if cx + d > width and cx > gap:
            row += 1
            cx = gap
        jitter = rng.uniform(-1.0, 1.0) * (params.r_max - r[i])
        x[i] = (cx + r[i], row * h + 0.5 * h + jitter)
        cx += d
    walls = np.array([0.0, width + gap, 0.0, (row + 1) * h])
    return x, r, walls


class CompactionReport(NamedTuple):
    porosity: float
    stress: tuple            # (s_xx, s_yy) [Pa]
    unbalanced: float
    steps: int
    converged: bool


def equilibrate(sim: Simulation, target, stress_tol, unbalanced_tol, max_steps, chunk=1000,
                progress=None):
    """Run under the current control until wall stresses are within stress_tol [Pa] of
    `target` (sx, sy) and the unbalanced-force ratio is below unbalanced_tol, or until
    max_steps.  Returns (converged, steps, unbalanced, stress)."""
    steps = 0
    target = np.asarray(target, float)
    while True:
        snap = sim.snapshot()
        s = sim.wall_stress(snap)
        ub = sim.unbalanced(snap)
        if np.all(np.abs(s - target) <= stress_tol) and ub <= unbalanced_tol:
            return True, steps, ub, s
        if steps >= max_steps:
            return False, steps, ub, s
        k = min(chunk, max_steps - steps)
        sim.run(k)
        steps += k
        if progress:
            progress(steps, s, ub)


def _kpa(s) -> str:
    """'(200.0, 200.0) kPa' of wall stresses (sx, sy) [Pa]."""
    return f"({s[0] / 1e3:.1f}, {s[1] / 1e3:.1f}) kPa"


def compact(params: DemParams, stress=200e3, friction_deg=0.0, stress_rel_tol=0.01,
            unbalanced_tol=1e-3, max_steps=3_000_000, compaction_damping=0.3,
            compaction_vmax=1.0, target_porosity=0.16, grow_step=0.005, grow_steps=500,
            verbose=False, allow_soft=False):
    """Generate and compact a sample isotropically to `stress` [Pa].

    Friction is `friction_deg` during compaction, then restored to params.phi_g and
    the sample re-equilibrated at the same stress.  The servo runs with a higher Cundall
    damping and wall speed cap during compaction only (faster; the final state is
    re-equilibrated with the nominal values).  Returns (Simulation, CompactionReport).
    A set outside the granular regime at `stress` is refused (``dem.regime.check_regime``,
    a ValueError) unless ``allow_soft``.
    """
    if not (0 <= friction_deg < 90):
        raise ValueError(f"friction_deg={friction_deg!r}; allowed range: 0 <= friction_deg < 90")
    if not stress > 0:
        raise ValueError(f"stress={stress!r}; allowed range: stress > 0 [Pa]")
    check_regime(params, stress, allow_soft)
    x, r, walls = generate(params)
    # Radius growth: start from the loose sample shrunk by s0 (radii and positions) and grow
    # the radii back to their values in place, walls servo-controlled at the target stress.
    # Every particle densifies at once, so the packing is homogeneous and no dense layer has
    # to be pushed through a granular gas by the walls (slow for 12,000 disks).
    phi0 = solid_fraction(r, walls)
    s0 = min(1.0, math.sqrt(phi0 / (1.0 - target_porosity)))
    # rolling resistance, like friction, is off while the sample densifies
    sim = Simulation.new(params, x * s0, r * s0, walls * s0,
                         mu=math.tan(math.radians(friction_deg)), mu_r=0.0)
    # masses and inertias are those of the final radii from the start: dt stays valid
    sim.m[:] = params.mass(r)
    sim.inertia[:] = params.inertia(r)
    sim.set_control(W.isotropic(stress))
    tol = stress_rel_tol * stress

    def prog(tag):
        if not verbose:
            return None
        def f(steps, s, ub):
            if steps % 20000 == 0:
                print(f"[compact {tag}] step {steps} s={_kpa(s)} "
                      f"unbalanced={ub:.2e} porosity={sim.porosity():.4f}", file=sys.stderr)
        return f

    sim.damping = compaction_damping
    sim.vmax_override = compaction_vmax
    n_grow = max(1, int(math.ceil((1.0 - s0) / grow_step)))
    for k in range(1, n_grow + 1):
        sim.r[:] = r * (s0 + (1.0 - s0) * k / n_grow)
        sim.rebuild()  # radii changed: gaps shrank without motion
        sim.run(grow_steps)
    sim.r[:] = r
    sim.rebuild()
    grown = n_grow * grow_steps
    if verbose:
        print(f"[compact] radii grown from {s0:.3f} in {grown} steps, porosity="
              f"{sim.porosity():.4f}, stress={_kpa(sim.wall_stress())}", file=sys.stderr)
    # the frictionless stage only has to densify: a 10x looser balance criterion (the
    # frictionless servo-controlled packing creeps slowly to 1e-3 for 12,000 disks); the
    # final state is checked with unbalanced_tol after the friction is restored
    ok1, st1, _, _ = equilibrate(sim, (stress, stress), tol, 10 * unbalanced_tol, max_steps,
                                 progress=prog("frictionless"))
    st1 += grown
    sim.vmax_override = None
    sim.damping = params.damping
    sim.mu = params.mu
    sim.mu_r = params.rolling_friction
    ok2, st2, ub, s = equilibrate(sim, (stress, stress), tol, unbalanced_tol, max_steps,
                                  progress=prog("friction restored"))
    sim.ref_len = sim.size.copy()
    rep = CompactionReport(sim.porosity(), (float(s[0]), float(s[1])), ub, st1 + st2, ok1 and ok2)
    if verbose:
        print(f"[compact] porosity={rep.porosity:.4f} stress={_kpa(rep.stress)} unbalanced={ub:.2e} "
              f"steps={rep.steps} converged={rep.converged}", file=sys.stderr)
    return sim, rep
