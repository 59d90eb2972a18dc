"""The contact law of a pair of disks: normal and tangential forces (``_contact_law``,
``_normal_force``) and the rolling moment (``_rolling_moment``).  Scalars in, scalars out: the
step kernels inline them in their pair loops."""
import math

from numba import njit

from .common import FAST


@njit(**FAST)
def _contact_law(dx, dy, rs, dvx, dvy, wr, ft_old, meff, kn, kt, mu, cap_on, beta, dt):
    """Linear spring contact law with incremental tangential spring and Coulomb cap, for one
    pair of disks i, j.  Scalars only: an array passed to a function called in a hot loop
    costs reference counting at every call (it halved the speed of the pair loop), scalars
    let the compiler inline it for free.  Branch-free: the forces of a pair that does not
    touch are computed and then zeroed (a quarter of the pairs of a dense sample are only
    within the skin, and a mispredicted branch cost more than the arithmetic).

    dx, dy = x_j - x_i [m]; rs = r_i + r_j [m]; dvx, dvy = v_j - v_i [m/s];
    wr = w_i r_i + w_j r_j [m/s]; ft_old: tangential history [N]; meff: reduced mass [kg]
    (used only with the normal dashpot).  fn = kn * overlap (+ dashpot, beta = fraction of
    critical damping), no tension (fn >= 0); ft += kt * (relative tangential velocity) * dt,
    |ft| <= mu fn when cap_on (cap_on = 0 means sliding prevented: the 'elastic' probes).
    Returns (touching, fx, fy, f_t, d_slip, d_dash): the force [N] on i by j and its
    tangential component, the new history (0 when the disks do not touch: cohesionless, the
    history is lost), and for the energy ledger (``dem.ledger``; unused values cost nothing,
    the compiler drops them) the energy [J] the step dissipates by sliding, (ft_old + f_t) / 2
    (f_trial - f_t) / kt (the step's mean force times the slip the cap takes out of its
    tangential displacement vt dt), and in the normal dashpot, its force times the step's
    normal approach -(v_n dt) (the half-step displacement the law integrates).
    """
    touch, nx, ny, fn = _normal_force(dx, dy, rs, dvx, dvy, meff, kn, beta)
    tx = -ny
    ty = nx
    vt = dvx * tx + dvy * ty - wr
    f_trial = ft_old + kt * vt * dt
    f_t = f_trial
    if cap_on:
        lim = mu * fn
        f_t = min(max(f_t, -lim), lim)
    fx = -fn * nx + f_t * tx
    fy = -fn * ny + f_t * ty
    # the force over the plastic increment is the step's mean (trapezoid): with f_t alone the
    # split of the contact work into stored and dissipated energy would be off by O(dt)
    # wherever mu fn varies during sliding (dem.ledger); 1/kt: hoisted out of the pair loop
    d_slip = 0.5 * (ft_old + f_t) * (f_trial - f_t) * (1.0 / kt)
    d_dash = 0.0
    if beta > 0.0:
        d_dash = (fn - kn * (rs - math.sqrt(dx * dx + dy * dy))) * -(dvx * nx + dvy * ny) * dt
    return (touch, fx if touch else 0.0, fy if touch else 0.0, f_t if touch else 0.0,
            d_slip if touch else 0.0, d_dash if touch else 0.0)


@njit(**FAST)
def _normal_force(dx, dy, rs, dvx, dvy, meff, kn, beta):
    """(touching, nx, ny, fn) of a pair: the unit normal from i to j and the normal force
    [N] (meaningless when not touching: the caller zeroes what it uses)."""
    d2 = dx * dx + dy * dy
    touch = d2 < rs * rs
    d = math.sqrt(d2)
    nx = dx / d
    ny = dy / d
    fn = kn * (rs - d)
    if beta > 0.0:
        fn -= 2.0 * beta * math.sqrt(kn * meff) * (dvx * nx + dvy * ny)
        fn = max(fn, 0.0)
    return touch, nx, ny, fn


@njit(**FAST)
def _rolling_moment(dx, dy, rs, dvx, dvy, meff, kn, beta, dw, mr_old, ri, rj, kr, mur,
                    cap_on, dt):
    """Elastic-plastic rolling resistance (Iwashita & Oda 1998; Ai et al. 2011 type C without
    the viscous part): the rolling moment on i [N m] after a step of relative rotation
    dw * dt, dw = w_i - w_j [rad/s]; stiffness k_r = kr R*^2 (kr = rolling_stiffness * kt
    [N/m]), capped at mu_r R* fn when cap_on, R* = r_i r_j / (r_i + r_j); 0 when the disks do
    not touch.  Disk j receives the opposite moment.  The normal force is the contact law's
    (``_normal_force``, same arguments).  Returns (M, d_roll): the moment and, for the energy
    ledger, the energy [J] the step dissipates by rolling plasticity, (M_old + M) / 2
    (M_trial - M) / k_r (0 below the cap; the step's mean moment, as ``_contact_law``'s
    sliding; unused values cost nothing)."""
    touch, _, _, fn = _normal_force(dx, dy, rs, dvx, dvy, meff, kn, beta)
    rstar = ri * rj / (ri + rj)
    m_trial = mr_old - kr * rstar * rstar * dw * dt
    m = m_trial
    if cap_on:
        lim = mur * rstar * fn
        m = min(max(m, -lim), lim)
    d_roll = 0.5 * (mr_old + m) * (m_trial - m) / (kr * rstar * rstar)
    return (m if touch else 0.0), (d_roll if touch else 0.0)
