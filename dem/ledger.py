"""The energy ledger of a DEM run: where the kinetic energy comes from (paper Eq. 1).

Definitions (leapfrog-consistent; docs/dem.md, "The energy ledger").  The kernel's
leapfrog is v(n+1/2) = v(n-1/2) + dt (F(n) + D(n)) / m, x(n+1) = x(n) + dt v(n+1/2), with F(n)
the contact and wall forces of step n and D(n) the Cundall damping force.  With the kinetic
energy at half steps, E_c(n+1/2) = sum 1/2 m v(n+1/2)^2 + 1/2 I w(n+1/2)^2, and the centred
displacement dx(n) = (x(n+1) - x(n-1)) / 2 = dt (v(n-1/2) + v(n+1/2)) / 2,

    E_c(n+1/2) - E_c(n-1/2) = sum_p (F_p(n) + D_p(n)) . dx_p(n)      (exactly, spins alike).

Split by who exerts the force: sum_p F_p . dx_p = W_ext - W_int, with

* ``w_ext``  = sum_w F_w(n) dU_w(n): the walls' work on the sample (F_w the wall's
  compressive force, dU_w its inward centred displacement, (d(n-1/2) + d(n+1/2)) / 2 with d
  the servo's move of a step); under a dead load (``walls.dead_load``) the dead load's work
  G_held dU1, the walls being then part of the system: their kinetic energy 1/2 m_G U1'^2 is
  in ``ke`` (the same leapfrog identity holds for them);
* ``w_int``  = sum_c f_c(n) . d delta_c(n): the work stored or spent in the contacts, signed so
  that an elastic contact being loaded gives W_int > 0 (delta the contact's relative
  displacement as compression, its tangential part and, with rolling resistance, the relative
  rotation).  The grain contacts' part is summed per disk, each disk's contact forces and
  moments times its centred displacement (by action and reaction the same sum as per contact,
  contacts created or lost included); the wall contacts' part per contact,
  f (dU_w - dx_p . inward);
* ``w_damp`` = sum_p D_p(n) . dx_p(n): the Cundall damping's work (< 0).

So dE_c = W_ext - W_int + W_damp closes to round-off, every term computed on its own
(``balance_residual``).  The contact work splits further into the stored elastic energy and the
dissipation, W_int = dE_el + D_slip + D_roll + D_dash: ``e_elastic`` is the elastic energy of
the contacts at the midpoint of the last step (``kernels.elastic_energy``: normal, tangential,
rolling, wall springs), ``d_slip`` f_t (f_trial - f_t) / kt summed over the steps' sliding
contacts, ``d_roll`` the same for the rolling moments, ``d_dash`` the normal dashpots' (off
unless ``normal_damping_ratio`` > 0).  This split holds only to O(dt^2) (the dissipations are
the steps' half-step increments; ``split_residual`` measures it, and its order is measured in
the tests by halving dt).

Eq. 1 in second-order form from t = 0 (the ledger's start: a probe's start or a switch): with
F_w(0), F_p(0) the wall forces and the disks' net forces of the first step, W1_ext =
sum_w F_w(0) U_w, U0 = sum_p F_p(0) . x_p (Eq. 14's unbalanced term, U_w and x_p the
displacements since 0 as sums of the centred ones), W1_int = W1_ext - U0 (= sum_c f_c(0) .
delta_c), W2_ext = W_ext - W1_ext and W2_int = W_int - W1_int (= sum_c (f_c - f_c(0)) . d
delta_c, the paper's Eq. 15 integrated, f = 0 where a contact is absent):

    E_c(t) - E_c(0) = W2_ext - W2_int + W_damp + U0      (``eq1_bookkeeping``).

The ledger only reads the trajectory (``kernels.advance``): a run has the same bits with it as
without it.  Its per-disk sums make every term independent of the number of threads, to the bit.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import kernels
from .walls import DEAD

# the columns the ledger adds to a history (fixed names: other tools read them)
COLUMNS = ["ke", "w_ext", "w_int", "w_damp", "e_elastic", "d_slip", "d_roll", "w2_ext", "w2_int",
           "u0", "eq1_bookkeeping"]
# and the ones beside them: the dashpot's dissipation, the rolling moments' and the wall
# contacts' shares of W_int, the residuals of the first-order balance and of the split of W_int,
# E_c - E_c(0) and the time since the start [s]
EXTRA_COLUMNS = ["d_dash", "w_int_roll", "w_int_wall", "balance_residual", "split_residual",
                 "dke", "t_ledger"]


class LedgerRecord(NamedTuple):
    """The ledger at one instant since its start t = 0 [J] (works and dissipations cumulative;
    ``ke`` and ``e_elastic`` the current values); residuals relative to the largest magnitude of
    their terms so far."""
    ke: float
    w_ext: float
    w_int: float
    w_damp: float
    e_elastic: float
    d_slip: float
    d_roll: float
    w2_ext: float
    w2_int: float
    u0: float
    eq1_bookkeeping: float
    d_dash: float
    w_int_roll: float
    w_int_wall: float
    balance_residual: float
    split_residual: float
    dke: float
    t_ledger: float

    def row(self):
        return [getattr(self, c) for c in COLUMNS + EXTRA_COLUMNS]


class Ledger:
    """The energy ledger of ``sim`` from now (t = 0); it attaches itself to ``sim`` (every
    later ``sim.run`` feeds it) until ``detach``.  ``read()`` gives a LedgerRecord."""

    def __init__(self, sim):
        self.sim = sim
        n = sim.n
        self.lsc = np.zeros(kernels.L_SIZE)
        self.led = np.zeros((6, n))
        self.F0 = np.zeros((n, 3))
        self.ke0 = kinetic_energy(sim)
        self.e_el0 = self.elastic_energy()
        self.x0, self.v0 = sim.x.copy(), sim.v.copy()
        self.w0, self.theta0 = sim.w.copy(), sim.theta.copy()
        self.step0 = sim.step
        self._max_bal = 0.0      # the largest magnitudes of the terms so far (residuals' scale)
        self._max_eq1 = 0.0
        self._max_split = 0.0
        sim.ledger = self

    _SAVED = ("lsc", "led", "F0", "x0", "v0", "w0", "theta0")

    def to_arrays(self) -> dict:
        """The ledger's state as named arrays (``io.save_state(..., arrays=)``), so that
        ``from_arrays`` continues it: a run resumed from a checkpoint keeps the same ledger, to
        the bit."""
        return dict({k: getattr(self, k) for k in self._SAVED}, step=np.array(self.sim.step),
                    step0=np.array(self.step0),
                    scalars=np.array([self.ke0, self.e_el0, self._max_bal, self._max_eq1,
                                      self._max_split]))

    @classmethod
    def from_arrays(cls, sim, d: dict) -> "Ledger":
        """The ledger of ``to_arrays`` at ``sim``'s step, attached to ``sim``. ValueError if the
        arrays are not a ledger's or belong to another step or sample."""
        if any(k not in d for k in cls._SAVED + ("step", "step0", "scalars")):
            raise ValueError("the checkpoint has no energy ledger (made by an older version)")
        if int(d["step"]) != sim.step or d["led"].shape != (6, sim.n):
            raise ValueError(f"the checkpoint's energy ledger belongs to another step or sample "
                             f"(step {int(d['step'])}, {d['led'].shape[1]} disks)")
        self = cls.__new__(cls)
        self.sim = sim
        for k in cls._SAVED:
            setattr(self, k, np.array(d[k], float))
        self.step0 = int(d["step0"])
        (self.ke0, self.e_el0, self._max_bal, self._max_eq1,
         self._max_split) = (float(v) for v in d["scalars"])
        sim.ledger = self
        return self

    def arrays(self):
        """(lsc, led, F0) for ``kernels.advance``."""
        return self.lsc, self.led, self.F0

    def detach(self):
        if self.sim.ledger is self:
            self.sim.ledger = None

    def elastic_energy(self) -> float:
        """The contacts' elastic energy now [J] (``kernels.elastic_energy``, summed)."""
        s = self.sim
        p = s.params
        pl = s.pairs
        return float(sum(kernels.elastic_energy(s.x, s.v, s.w, s.r, s.walls, s.prev, pl.pi, pl.pj,
                                                pl.ft, pl.mr, p.kn, p.kt,
                                                p.rolling_stiffness * p.kt, s.mu_r > 0, s.dt)))

    def displacements(self):
        """(dx (N, 2) [m], dtheta (N,) [rad]): the sums of the centred displacements since the
        start, x(n+1) - x(n0) - dt (v(n+1/2) - v(n0-1/2)) / 2 (telescoped)."""
        s = self.sim
        h = 0.5 * s.dt
        return (s.x - self.x0) - h * (s.v - self.v0), (s.theta - self.theta0) - h * (s.w - self.w0)

    def read(self) -> LedgerRecord:
        s = self.sim
        L, K = self.lsc, kernels
        ke = kinetic_energy(s)
        w_ext = float(L[K.L_W_EXT])
        w_roll = -float(np.sum(self.led[5]))
        w_wall = float(L[K.L_W_INT_WALL])
        w_int = -float(np.sum(self.led[0])) + w_roll + w_wall
        w_damp = float(np.sum(self.led[1]))
        d_slip = float(np.sum(self.led[2]))
        d_roll = float(np.sum(self.led[3]))
        d_dash = float(np.sum(self.led[4])) + float(L[K.L_D_DASH_WALL])
        e_el = self.elastic_energy()
        if L[K.L_STARTED]:
            dx, dth = self.displacements()
            u0 = float(np.sum(self.F0[:, :2] * dx) + np.sum(self.F0[:, 2] * dth))
            w1_ext = float(np.dot(L[K.L_FW0:K.L_FW0 + 4], L[K.L_DU:K.L_DU + 4]))
        else:
            u0 = w1_ext = 0.0
        w2_ext = w_ext - w1_ext
        w2_int = w_int - (w1_ext - u0)
        dke = ke - self.ke0
        self._max_bal = max(self._max_bal, abs(dke), abs(w_ext), abs(w_int), abs(w_damp))
        self._max_eq1 = max(self._max_eq1, abs(dke), abs(w2_ext), abs(w2_int), abs(w_damp),
                            abs(u0))
        de_el = e_el - self.e_el0
        self._max_split = max(self._max_split, abs(w_int), abs(de_el), d_slip, d_roll, abs(d_dash))
        rel = lambda r, scale: abs(r) / scale if scale > 0 else 0.0
        return LedgerRecord(
            ke, w_ext, w_int, w_damp, e_el, d_slip, d_roll, w2_ext, w2_int, u0,
            rel(dke - (w2_ext - w2_int + w_damp + u0), self._max_eq1), d_dash, w_roll, w_wall,
            rel(dke - (w_ext - w_int + w_damp), self._max_bal),
            rel(w_int - de_el - d_slip - d_roll - d_dash, self._max_split), dke,
            (s.step - self.step0) * s.dt)


def kinetic_energy(sim) -> float:
    """E_c [J] at the half step: the disks', and under a dead load (``walls.dead_load``) the
    walls', 1/2 m_G U1'^2 with U1' (n+1/2) = (d_bottom + d_top) / dt, their last moves."""
    ke = sim.kinetic_energy()
    c = sim.control
    if c.mode[1] == DEAD:
        ke += 0.5 * c.wall_mass * ((sim.prev[2] + sim.prev[3]) / sim.dt) ** 2
    return ke


def max_eq1_bookkeeping(history, columns) -> float:
    """The largest ``eq1_bookkeeping`` of a history (rows with ``columns``), the ``eq1_bookkeeping``
    column of probes.csv and burst.csv."""
    h = np.asarray(history, float)
    if h.size == 0:
        return math.nan
    return float(np.max(h[:, list(columns).index("eq1_bookkeeping")]))


def plot_ledger(path, panels):
    """One PNG of Eq. 1's terms against the time since the start, one panel per (title, rows,
    columns) in ``panels`` (a run's history: ``rows`` with ``columns`` names, which must hold
    the ledger's ``t_ledger``, ``dke``, ``w2_ext``, ``w2_int``, ``w_damp``, ``u0``). Symmetric
    log axis (the terms span decades; ``common.plots.symlog_axis``: no tick labels piled at 0).
    The sum W2_ext - W2_int + W_damp + U0 is drawn dotted on E_c - E_c(0) (Eq. 1: they
    coincide). One legend below the panels (the terms are the same in each), off the curves."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from common.io import save_figure
    from common.plots import symlog_axis
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 5.0), squeeze=False,
                             layout="constrained")
    for ax, (title, rows, columns) in zip(axes[0], panels):
        h = np.asarray(rows, float)
        col = {c: k for k, c in enumerate(columns)}
        t = h[:, col["t_ledger"]]
        dke = h[:, col["dke"]]
        terms = [(dke, r"$E_c - E_c(0)$", "k", "-", 2.2),
                 (h[:, col["w2_ext"]], r"$W_2^{ext}$ (walls)", "C0", "-", 1.4),
                 (-h[:, col["w2_int"]], r"$-W_2^{int}$ (given up by the contacts)", "C3", "-", 1.4),
                 (h[:, col["w_damp"]], r"$W_{damp}$ (Cundall damping)", "C2", "-", 1.4),
                 (h[:, col["u0"]], r"$U_0$ (unbalanced at $t = 0$)", "C4", "--", 1.0)]
        for y, lab, c, ls, lw in terms:
            ax.plot(t, y, ls, color=c, lw=lw, label=lab)
        total = h[:, col["w2_ext"]] - h[:, col["w2_int"]] + h[:, col["w_damp"]] + h[:, col["u0"]]
        ax.plot(t, total, ":", color="y", lw=1.2,
                label=r"$W_2^{ext} - W_2^{int} + W_{damp} + U_0$ (Eq. 1)")
        big = max([float(np.nanmax(np.abs(y))) for y, *_ in terms if np.isfinite(y).any()] + [0.0])
        symlog_axis(ax, max(big * 1e-4, 1e-12))
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_xlabel("time since the start [s]")
        ax.set_ylabel("energy since the start [J]")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    save_figure(fig, path, dpi=120)


def redraw_burst_ledger(out_dir):
    """fig_burst_ledger.png of a finished ``dem burst`` folder drawn again from its history.csv,
    burst.csv and summary.json, as the run draws it (Eq. 1's terms of the first path's below and
    past runs), without a run: ``python -c "from dem.ledger import redraw_burst_ledger;
    redraw_burst_ledger('DIR')"``."""
    import csv
    import json
    import os
    with open(os.path.join(out_dir, "summary.json")) as f:
        n = json.load(f)["n_disks"]
    with open(os.path.join(out_dir, "burst.csv"), newline="") as f:
        runs = list(csv.DictReader(f))
    with open(os.path.join(out_dir, "history.csv"), newline="") as f:
        hist = list(csv.DictReader(f))
    first = (runs[0]["ratio"], runs[0]["start_fraction"])
    columns = [c for c in hist[0] if c not in ("ratio", "start_fraction", "switch")]
    panels = []
    for r in runs:
        if (r["ratio"], r["start_fraction"]) != first:
            continue
        rows = [[float(x[c]) for c in columns] for x in hist
                if x["switch"] == r["switch"] and (x["ratio"], x["start_fraction"]) == first]
        panels.append((f"R = {float(r['ratio']):g}, f = {float(r['start_fraction']):g}, "
                       f"{r['switch']}: {r['outcome']} ({n} disks)", rows, columns))
    if panels:
        plot_ledger(os.path.join(out_dir, "fig_burst_ledger.png"), panels)
