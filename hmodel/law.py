"""The H-model as a material of the contract (``point.contract``): the law the analysis finds
from ``HParams`` (``point.material_of``), with its Numba fast paths behind the contract.

Everything here gives the numbers the generic code gives from ``update`` (the tests compare
them): ``update_rows`` is ``material.update_copies`` (the probes' batches without wrapping
states), ``mixed_step_fast`` the kernel ``mixed_step_single`` (the same Newton with
backtracking), ``run_path_fast`` the kernel ``path_single`` run ``chunk`` steps at a time.
What only the H-model provides: the Lagrangian increment dPi and the transport term T3 (the
paper's W2, Eq. 10, and its Eulerian split, Eq. 38), the micro sums (Eqs. 36-37), the patterns
of sliding and open hexagons.
"""
from __future__ import annotations

import numpy as np

from point.contract import Material, MaterialError, Rows, register
from point.controllability import PathEnd, describe_control, stress_name
from point.driver import PathResult, _Cut, _Progress, _tensor, compressed_state
from point.tensors import to_voigt

from . import _kernels
from .material import (HState, HEX_FIELDS, PARALLEL_MIN_POINTS, broadcast_state, check_state,
                       from_voigt, increment_from_outputs, kernel_args, reference_state,
                       take_points, update, update_copies, update_full, _material_args,
                       _refuse_non_finite)
from .params import HParams, UNITS

__all__ = ["HModel", "HMODEL"]

# the kernel's outputs by name (``_kernels.allocate_outputs`` order)
OUTPUTS = ("d1", "d2", "alpha", "N1", "T1", "N2", "l1", "l2", "cos_alpha", "sin_alpha",
           "sliding", "is_open", "stress", "tangent", "tangent_lagrangian", "dPi", "T3",
           "w2_hex", "w2n", "w2t")
assert OUTPUTS[:10] == HEX_FIELDS


class HModel(Material):
    """The H-microdirectional model (Nicot & Darve 2011) of ``hmodel.material``."""

    name = "hmodel"
    params_type = HParams
    units = UNITS
    provides = frozenset({"lagrangian", "micro", "patterns"})
    description = "the H-microdirectional model (hexagons of grains, Nicot & Darve 2011)"
    # the tangent of a step is the exact derivative of its stress, piecewise constant for a fixed
    # sliding pattern: the rate tangent at the state the step reaches, on the step's branch
    tangent_is_rate = True
    label = "H-model"
    defaults_name = "Table I"

    def initial_state(self, params: HParams, batch_shape: tuple = ()) -> HState:
        """From d1 = d2 = 2 r_g, alpha = alpha0 compressed isotropically to p0 (MixedControlError
        when the compression has no static state on its way)."""
        s = compressed_state(params, params.p0)
        return s if tuple(batch_shape) == () else broadcast_state(s, batch_shape)

    def reference_state(self, params: HParams, batch_shape: tuple = ()) -> HState:
        return reference_state(params, batch_shape)

    def update(self, state, d_eps, params):
        return update(state, d_eps, params)

    def full_update(self, state, d_eps, params):
        """``hmodel.material.update_full``: the Increment with the Lagrangian tangent and
        increment, T3 and the micro sums."""
        return update_full(state, d_eps, params)

    def elastic_update(self, state, d_eps, params):
        inc = update_full(state, d_eps, params, allow_sliding=False, extras=False)
        return inc.stress, inc.tangent, inc.state

    def check_state(self, state, params) -> None:
        if not isinstance(state, HState):
            raise MaterialError(f"material {self.name}: a state of type {type(state).__name__}, "
                                "allowed an HState")
        check_state(state, params)

    def broadcast(self, state, batch_shape):
        return broadcast_state(state, batch_shape)

    def take(self, state, index):
        return take_points(state, index)

    def volume(self, state) -> np.ndarray:
        return state.volume

    def counts(self, state) -> tuple:
        return int(state.sliding.sum()), int(state.is_open.sum())

    def update_rows(self, state, de, params, elastic: bool = False, extras: bool = True) -> Rows:
        out = update_copies(state, de, params, allow_sliding=not elastic, extras=extras)
        named = dict(zip(OUTPUTS, out))
        closed = ~named["is_open"]
        return Rows(named["stress"], named["tangent"], np.any(named["sliding"] & closed, axis=-1),
                    named)

    def update_voigt(self, state, de, params, elastic: bool = False) -> tuple:
        """``Material.update_voigt`` by the update kernel called here directly: the same checks
        and the same bits as ``update_full(state, de as tensors, params, allow_sliding=not
        elastic, extras=False)``, the stress and tangent rows as the kernel gives them (no
        Lagrangian tangent, increment or T3 conversions a field never reads). The outputs are new
        arrays at every call, as in ``update_full``: pooled buffers saved a few page faults but
        changed how the process's heap serves other large arrays (the FE benchmark's batch
        baseline, interleaved with the run, then took ~4500 page faults a call and twice the
        time)."""
        check_state(state, params)
        args = kernel_args(state, params)          # 10 hexagon fields, was_open, eps, V0, eps
        npts, ndir = args[0].shape
        out = _kernels.allocate_outputs(npts, ndir)
        kern = _kernels.update_parallel if npts >= PARALLEL_MIN_POINTS else _kernels.update_serial
        kern(*args[:-1], de, *_material_args(params), not elastic, False, *out)
        o = dict(zip(OUTPUTS, out))
        sig, tan = o["stress"], o["tangent"]
        if not (np.isfinite(sig).all() and np.isfinite(tan).all()):
            _refuse_non_finite(state)
        batch = state.batch_shape
        ns = HState(*(o[f] for f in HEX_FIELDS), eps=state.eps + from_voigt(de, batch),
                    stress=from_voigt(sig, batch), V0=np.array(state.V0, dtype=float),
                    sliding=o["sliding"], is_open=o["is_open"], params_key=state.params_key)
        return ns, sig, tan

    def point_fractions(self, state) -> tuple:
        """(sliding, opened): (n,) fractions of each point's hexagons that slid / are open."""
        n = state.n_dir
        return (_kernels.row_fractions(state.sliding.reshape(-1, n)),
                _kernels.row_fractions(state.is_open.reshape(-1, n)))

    def flags_changed(self, a, b) -> int:
        """The hexagons whose sliding or opening flag differs between two states."""
        return int(_kernels.n_differ(a.sliding, b.sliding) + _kernels.n_differ(a.is_open, b.is_open))

    def pattern_changes(self, state, params, de_a, de_b) -> dict:
        """The orientations whose open / sliding flags differ between the increments de_a and
        de_b (3,) from ``state``: theta [deg], N1, N2 [N] and alpha [deg] where each is closed,
        whether it opens (rather than starts or stops sliding) and by which contacts. With
        ``state`` None: the record of no change."""
        if state is None:
            return {"theta": [], "N1": [], "N2": [], "alpha": [], "opens": [], "via": [], "count": 0}
        o = dict(zip(OUTPUTS, update_copies(state, np.vstack([de_a, de_b]), params, extras=False)))
        sl, op, N1, N2, al = o["sliding"], o["is_open"], o["N1"], o["N2"], o["alpha"]
        diff = np.flatnonzero((sl[0] != sl[1]) | (op[0] != op[1]))
        closed = [0 if not op[0, i] else 1 for i in diff]
        opens = [bool(op[0, i] != op[1, i]) for i in diff]
        # by which contacts it opens: the one whose force is ~0 on the closed side (it reaches 0
        # continuously; the opening rule drops the other one)
        via = [("axial" if N2[c, i] < N1[c, i] else "inclined") if o else ""
               for c, i, o in zip(closed, diff, opens)]
        return {"theta": [float(x) for x in np.degrees(params.theta)[diff]],
                "N1": [float(N1[c, i]) for c, i in zip(closed, diff)],
                "N2": [float(N2[c, i]) for c, i in zip(closed, diff)],
                "alpha": [float(np.degrees(al[c, i])) for c, i in zip(closed, diff)],
                "opens": opens, "via": via, "count": int(diff.size)}

    def fit_space(self):
        """What a fit of the H-model frees, and how (``hmodel.fit.SPACE``)."""
        from .fit import SPACE
        return SPACE

    def kernels(self) -> tuple:
        """The Numba kernels a first run compiles (``point.experiment.compile_kernels``)."""
        return (_kernels.update_serial, _kernels.update_parallel, _kernels.mixed_step_single,
                _kernels.path_single, _kernels.row_fractions, _kernels.n_differ)

    def warm_up(self) -> None:
        """Compile the kernels on a tiny case (n_dir = 8)."""
        from point.driver import drained_biaxial, mixed_step
        from point.probes import strain_probes
        p = HParams(n_dir=8)
        s = self.initial_state(p)                                   # path_single
        mixed_step(s, p, drained_biaxial(1e-5), [0.0, p.p0, 0.0])     # mixed_step_single
        update_full(s, np.zeros((2, 2)), p)                          # update_serial
        strain_probes(s, p, np.linspace(0.0, 360.0, 64, endpoint=False))   # update_parallel
        self.flags_changed(s, s)                                     # n_differ
        self.point_fractions(broadcast_state(s, (2,)))               # row_fractions

    # -- the fast paths ------------------------------------------------------------------------
    def mixed_step_fast(self, state, params, control, target, guess, tol, max_iter):
        """``point.mixed``'s Newton by the kernel ``mixed_step_single``: (iterations, residual,
        Increment, d_eps (3,))."""
        sc = np.array(control.strain_controlled, dtype=np.bool_)
        general, A, Ainv = control.matrices()
        de = np.zeros(3) if guess is None else np.array(guess, dtype=float)
        if general:
            de = A @ de
        de[sc] = np.asarray(control.d_eps)[sc]
        args = kernel_args(state, params)
        out = _kernels.allocate_outputs(1, state.n_dir)
        it, rn, de_out = _kernels.mixed_step_single(
            *args[:-1], *_material_args(params), True, True, sc, de, target, tol, int(max_iter),
            *out, general, Ainv)
        return int(it), rn, increment_from_outputs(state, de_out, out), de_out[0].copy()

    def run_path_fast(self, state, params, control, n_steps, until, progress, label, cut, rtol,
                      max_iter, chunk):
        """``point.driver.run_path`` in the kernel ``path_single``, ``chunk`` steps at a time."""
        sig0 = to_voigt(state.stress)[0]
        general, A, Ainv = control.matrices()
        s0 = control.to_controlled(v_stress=sig0) if general else sig0
        scale = max(float(np.max(np.abs(s0))), float(np.max(np.abs(s0 + n_steps * np.asarray(control.d_sigma)))),
                    1e-3 * params.p0)
        tol = rtol * scale
        cut.tol = tol
        work = [a.copy() for a in kernel_args(state, params)[:-1]]
        sliding = np.ascontiguousarray(state.sliding, dtype=np.bool_).reshape(1, -1).copy()
        margs = _material_args(params)
        sc = np.array(control.strain_controlled, dtype=np.bool_)
        d_eps = np.asarray(control.d_eps, dtype=float)
        d_sig = np.asarray(control.d_sigma, dtype=float)
        h_de = np.zeros((n_steps, 3)); h_sig = np.zeros((n_steps, 3))
        h_it = np.zeros(n_steps, dtype=np.int64); h_nsl = np.zeros(n_steps, dtype=np.int64)
        h_nop = np.zeros(n_steps, dtype=np.int64); h_cut = np.zeros(n_steps, dtype=np.int64)
        guess = np.zeros(3)
        done = have = 0
        bar = _Progress(n_steps, label) if progress else None
        end = None

        def result(rows):
            return _path_result(state, work, sliding, sig0, h_de[:rows], h_sig[:rows], h_it[:rows],
                                h_nsl[:rows], h_nop[:rows], h_cut[:rows], control, end)

        try:
            while done < n_steps:
                m = min(int(chunk), n_steps - done)
                saved = [a.copy() for a in work] + [sliding.copy()]
                sl = slice(done, done + m)
                n, rn, code = _kernels.path_single(*work, *margs, sc, d_eps, s0, d_sig, done, m, guess, tol,
                                             int(max_iter), h_de[sl], h_sig[sl], h_it[sl], h_nsl[sl],
                                             h_nop[sl], sliding, general, A, Ainv)
                have = done + n                    # the rows the state in ``work`` has reached
                stop_at = None
                if until is not None and n > 0:
                    eps_rows = np.cumsum(h_de[:done + n], axis=0)[done:]
                    for j in range(n):
                        if until(eps_rows[j], h_sig[done + j]):
                            stop_at = j
                            break
                if stop_at is not None and stop_at + 1 < n:
                    work = saved[:-1]
                    sliding = saved[-1]
                    have = done
                    n, rn, code = _kernels.path_single(*work, *margs, sc, d_eps, s0, d_sig, done, stop_at + 1,
                                                 guess, tol, int(max_iter), h_de[sl], h_sig[sl], h_it[sl],
                                                 h_nsl[sl], h_nop[sl], sliding, general, A, Ainv)
                have = done + n
                if n > 0:
                    guess = h_de[done + n - 1].copy()
                done += n
                if bar is not None:
                    bar.update(done)
                if stop_at is not None:
                    break
                if n < m:
                    # step done + 1 did not converge whole: its substeps from the state in ``work``
                    here = _state_from_work(state, work, sliding, h_sig[done - 1] if done else sig0)
                    c = cut.step(here, done + 1, guess)
                    h_de[done], h_sig[done], h_it[done] = c.de, c.sigma, c.iterations
                    h_cut[done] = c.cuts
                    if c.end is not None or c.fraction > 0:
                        h_nsl[done] = int(c.state.sliding.sum())
                        h_nop[done] = int(c.state.is_open.sum())
                        work = [a.copy() for a in kernel_args(c.state, params)[:-1]]
                        sliding = np.ascontiguousarray(c.state.sliding, dtype=np.bool_).reshape(1, -1).copy()
                        have = done + (1 if c.fraction > 0 else 0)
                    if c.end is not None:
                        end = (c.end, done + 1, c.fraction)
                        done += 1 if c.fraction > 0 else 0
                        break
                    guess = c.de.copy()
                    done += 1
                    if bar is not None:
                        bar.update(done)
                    if until is not None and until(np.cumsum(h_de[:done], axis=0)[-1], h_sig[done - 1]):
                        break
        except BaseException as e:
            if not hasattr(e, "partial"):
                e.partial = result(have)
            raise
        finally:
            if bar is not None:
                bar.close()
        return result(done)




def _state_from_work(state, work, sliding, sig) -> HState:
    """The HState of the kernel's work arrays (the state of a path in its Numba loop)."""
    n = state.n_dir
    d1, d2, al, N1, T1, N2, l1, l2, ca, sa, was_open, eps, V0 = work
    return HState(d1=d1.reshape(n).copy(), d2=d2.reshape(n).copy(), alpha=al.reshape(n).copy(),
                  N1=N1.reshape(n).copy(), T1=T1.reshape(n).copy(), N2=N2.reshape(n).copy(),
                  l1=l1.reshape(n).copy(), l2=l2.reshape(n).copy(),
                  cos_alpha=ca.reshape(n).copy(), sin_alpha=sa.reshape(n).copy(),
                  eps=_tensor(eps[0]), stress=_tensor(sig), V0=np.array(float(V0[0])),
                  sliding=sliding.reshape(n).copy(), is_open=was_open.reshape(n).copy(),
                  params_key=state.params_key)


def _path_result(state, work, sliding, sig0, h_de, h_sig, h_it, h_nsl, h_nop, h_cut, control,
                 end) -> PathResult:
    last_sig = h_sig[-1] if len(h_sig) else sig0
    final = _state_from_work(state, work, sliding, last_sig)
    eps = np.vstack([np.zeros(3), np.cumsum(h_de, axis=0)])
    sigma = np.vstack([sig0, h_sig])
    pe = PathEnd("complete", 0, 1.0, eps[-1].copy(), sigma[-1].copy(), describe_control(control),
                 None)
    if end is not None:
        v, k, f = end
        pe = pe._replace(outcome=v.outcome, step=k, fraction=f, verdict=v,
                         stress=stress_name(control, v.variable))
    return PathResult(
        eps=eps, sigma=sigma,
        newton_iters=np.concatenate([[0], h_it]),
        n_sliding=np.concatenate([[int(state.sliding.sum())], h_nsl]),
        n_open=np.concatenate([[int(state.is_open.sum())], h_nop]), state=final, states=None,
        cuts=np.concatenate([[0], h_cut]), end=pe)



HMODEL = register(HModel())
