"""The step kernel against a plain one-loop step written in Python, to the bit.

The kernel computes the contact law of a block's pairs in chunks and passes (gather, law, sums)
and the leapfrog on flat views, so that the compiler vectorizes them (``dem.kernels``,
``_block_step``). None of that may change a single operation: this reference does one pair at a
time in increasing pair index, each force added to both disks as it is computed, then the
Cundall damping and the leapfrog disk by disk, in Python floats (IEEE doubles, the same
operations in the same order). Walls and servo are the kernel's own functions (unchanged), so the
comparison is on the pair forces, the rolling moments and the integration. Conditions: a
friction low enough that many contacts slide at the Coulomb cap, Cundall damping on, the normal
dashpot off and on, the elastic probes' uncapped law, rolling resistance off and on, one block
(two chunks of pairs: the 200-disk sample has about 480 pairs) and three blocks (cross pairs).
"""
import math

import numpy as np
import pytest

from dem import kernels
from dem.simulation import Simulation


def _law(dx, dy, rs, dvx, dvy, wr, ft_old, meff, kn, kt, mu, cap_on, beta, dt):
    d2 = dx * dx + dy * dy
    touch = d2 < rs * rs
    d = math.sqrt(d2)
    nx = dx / d
    ny = dy / d
    fn = kn * (rs - d)
    if beta > 0.0:
        fn -= 2.0 * beta * math.sqrt(kn * meff) * (dvx * nx + dvy * ny)
        fn = max(fn, 0.0)
    tx, ty = -ny, nx
    vt = dvx * tx + dvy * ty - wr
    f_t = ft_old + kt * vt * dt
    capped = False
    if cap_on:
        lim = mu * fn
        capped = touch and abs(f_t) > lim
        f_t = min(max(f_t, -lim), lim)
    if not touch:
        return 0.0, 0.0, 0.0, False
    return -fn * nx + f_t * tx, -fn * ny + f_t * ty, f_t, capped


def _rolling(dx, dy, rs, dvx, dvy, meff, kn, beta, dw, mr_old, ri, rj, kr, mur, cap_on, dt):
    d = math.sqrt(dx * dx + dy * dy)
    touch = dx * dx + dy * dy < rs * rs
    fn = kn * (rs - d)
    if beta > 0.0:
        fn -= 2.0 * beta * math.sqrt(kn * meff) * (dvx * (dx / d) + dvy * (dy / d))
        fn = max(fn, 0.0)
    rstar = ri * rj / (ri + rj)
    m = mr_old - kr * rstar * rstar * dw * dt
    if cap_on:
        lim = mur * rstar * fn
        m = min(max(m, -lim), lim)
    return m if touch else 0.0


def _sign(a):
    return 1.0 if a > 0 else (-1.0 if a < 0 else 0.0)


def _reference_step(s, ft, mr, fext, kn, kt, mu, cap_on, beta, kr, mur, damping, dt):
    """One step of the disks of ``s`` (a Simulation's arrays, modified in place) after the wall
    forces fext: pairs in increasing index (then, with rolling resistance, their rolling
    moments, in the same order), then the leapfrog. Returns the number of contacts whose
    tangential force was capped by Coulomb's law."""
    x, v, w, r, m, inertia, theta = s.x, s.v, s.w, s.r, s.m, s.inertia, s.theta
    pi, pj = s.pairs.pi, s.pairs.pj
    fnet = np.zeros((s.n, 4))
    fnet[:, :2] = fext
    if mur > 0.0:           # positions and velocities of the step's start
        for k in range(pi.size):
            i, j = int(pi[k]), int(pj[k])
            meff = m[i] * m[j] / (m[i] + m[j]) if beta > 0.0 else 0.0
            mr[k] = _rolling(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], r[i] + r[j],
                             v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], meff, kn, beta, w[i] - w[j],
                             mr[k], r[i], r[j], kr, mur, cap_on, dt)
            fnet[i, 3] += mr[k]
            fnet[j, 3] -= mr[k]
    n_capped = 0
    for k in range(pi.size):
        i, j = int(pi[k]), int(pj[k])
        meff = m[i] * m[j] / (m[i] + m[j]) if beta > 0.0 else 0.0
        fx, fy, f_t, capped = _law(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], r[i] + r[j],
                           v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], w[i] * r[i] + w[j] * r[j],
                           ft[k], meff, kn, kt, mu, cap_on, beta, dt)
        n_capped += capped
        ft[k] = f_t
        fnet[i, 0] += fx
        fnet[i, 1] += fy
        fnet[i, 2] += f_t
        fnet[j, 0] -= fx
        fnet[j, 1] -= fy
        fnet[j, 2] += f_t
    for p in range(s.n):
        fx, fy, tq = fnet[p, 0], fnet[p, 1], fnet[p, 2] * r[p]
        if mur > 0.0:
            tq += fnet[p, 3]
        if damping > 0.0:
            fx -= damping * abs(fx) * _sign(v[p, 0])
            fy -= damping * abs(fy) * _sign(v[p, 1])
            tq -= damping * abs(tq) * _sign(w[p])
        v[p, 0] += fx / m[p] * dt
        v[p, 1] += fy / m[p] * dt
        w[p] += tq / inertia[p] * dt
        x[p, 0] += v[p, 0] * dt
        x[p, 1] += v[p, 1] * dt
        theta[p] += w[p] * dt
    return n_capped


def _kernel_steps(s, nsteps, kn, kt, mu, cap_on, beta, kr, mur, damping, nblocks, ref, ref_ft,
                  ref_mr):
    """``nsteps`` single-step calls of kernels.advance on ``s`` (strain-rate control of both
    axes: the servo moves the walls at a fixed rate) and the same steps of the reference
    ``ref``, compared after every step. Returns the capped contacts of each step."""
    p = s.params
    pl = s.pairs
    mode = np.array([1, 1], np.int64)
    rate = np.array([-0.5, 2.0])        # x walls open, y walls close [1/s]
    zero2 = np.zeros(2)
    len0 = np.array([s.walls[1] - s.walls[0], s.walls[3] - s.walls[2]])
    capped = []
    for step in range(nsteps):
        # the wall forces of the reference: the kernel's own (unchanged) function
        fext = np.zeros((ref.n, 2))
        kernels.wall_forces(ref.x, ref.v, ref.r, ref.m, ref.walls, ref.pairs.cand_off,
                            ref.pairs.cand, fext, kn, beta, np.zeros(4), np.zeros(4),
                            np.zeros((2, 0)))
        kernels.advance(1, tuple(kernels.Disks(s.x, s.v, s.w, s.theta, s.r, s.m, s.inertia,
                                               s.fext, s.fnet, s.x_ref, s.disp2)), tuple(pl),
                        tuple(kernels.WallState(s.walls, s.walls_ref, s.prev, s.wF, s.wK)),
                        tuple(kernels.Servo(mode, zero2, zero2, 0, 0, rate, len0, 0.0, 0.0, 0.0,
                                            p.thickness, p.servo_gain, p.servo_smoothing,
                                            p.servo_vmax)),
                        tuple(kernels.Law(kn, kt, mu, cap_on, beta, kr, mur, damping, s.dt)),
                        step, 0.5 * p.skin, nblocks,
                        (np.zeros(0), np.zeros((6, 0)), np.zeros((0, 3))))
        capped.append(_reference_step(ref, ref_ft, ref_mr, fext, kn, kt, mu, cap_on, beta, kr,
                                      mur, damping, s.dt))
        ref.walls[:] = s.walls        # the servo moved them by a prescribed rate
        for a, b in ((s.x, ref.x), (s.v, ref.v), (s.w, ref.w), (s.theta, ref.theta),
                     (pl.ft, ref_ft), (pl.mr, ref_mr)):
            assert np.array_equal(a, b), f"step {step}: the kernel left the reference"
    return capped


@pytest.mark.parametrize("mur", [0.0, 0.1])
@pytest.mark.parametrize("beta", [0.0, 0.3])
@pytest.mark.parametrize("nblocks", [1, 3])
@pytest.mark.parametrize("cap_on", [True, False])
def test_kernel_step_is_the_one_loop_step_to_the_bit(small_sample, beta, nblocks, cap_on, mur):
    s = Simulation(small_sample)
    ref = Simulation(small_sample)
    p = s.params
    mu = 0.05               # low friction: many contacts reach the Coulomb cap
    kn, kt, damping = p.kn, p.kt, 0.15
    kr = 1.0 * kt           # rolling stiffness factor 1 (DemParams' default) x kt [N/m]
    ref_ft = ref.pairs.ft.copy()
    ref_mr = ref.pairs.mr.copy()
    assert s.pairs.pi.size > kernels.CHUNK, "the sample must give more than one chunk of pairs"
    # disks set moving and spinning: contacts load, slide and open
    dv = np.random.default_rng(0).normal(0.0, 1e-3, s.v.shape)      # [m/s]
    dw = np.random.default_rng(1).normal(0.0, 1.0, s.w.shape)       # [rad/s]
    for a in (s, ref):
        a.v += dv
        a.w += dw
    capped = _kernel_steps(s, 40, kn, kt, mu, cap_on, beta, kr, mur, damping, nblocks, ref,
                           ref_ft, ref_mr)
    touching = np.count_nonzero(ref_ft)
    assert touching > s.n       # a dense sample: more contacts than disks
    if cap_on:                  # the Coulomb cap acts on a good share of them by the end
        assert capped[-1] > 0.1 * touching, capped
    else:
        assert max(capped) == 0
    if mur > 0.0:               # rolling moments carried by the contacts (spun disks)
        assert np.count_nonzero(ref_mr) > 0.5 * touching
    else:
        assert not np.any(ref_mr)
