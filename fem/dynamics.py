"""Dynamics of the biaxial specimen held at a generalized force (docs/burst.md; paper Eq. 1).

    M u'' + C u' + f_int(u) = f_ext,      per unit thickness (forces N/m, masses kg/m)

Kept apart, each with its own test (tests/fem/test_dynamics.py):

* the mass (``mass_matrix``): consistent, M_ij = int rho N_i . N_j dA, exact for the bilinear
  quads and linear triangles of fem.mesh (a 2-point Gauss rule a direction / a 3-point rule);
* the boundary conditions (``Tie``): rigid smooth platens on the four faces, the lateral ones
  tied to the axial one along the proportional strain path d eps2 = R d eps1, all moved by one
  generalized displacement U1 [m] (axial shortening, compression positive) whose conjugate force
  is G = F1 + R (B/H) F2 = B c [N/m], c = s1 + R s2 [Pa];
* the integrator (``Newmark``, ``newmark_step``): Newmark's scheme on the reduced system, Newton
  with the consistent tangent, the material updated through its one contract (the total strain
  increment of the time step from the committed state, committed on convergence);
* the run at a held force (``hold``): from a static state at rest, G_ext = G_switch + dG held,
  every step recorded (energies of Eq. 1; Newmark's own balance, which measures the Newton
  residual; the energy check from the material's stresses and the density, which Newmark
  cannot satisfy by itself), the outcome decided by ``hmodel.burst_rule.decide``, a time step
  that converges at no substep reported as 'not_converged'.

Sign conventions: the FE is tension positive (fem.adapter); U1, G, c, eps1, eps2 are compression
positive (docs/burst.md).
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Basis, BilinearForm
from skfem.helpers import dot

from point.burst import Specimen
from point.burst_rule import BurstRule, EnergyCheck, decide
from point.driver import MAX_CUTS
from .problem import Biaxial
from .solver import FreeSolver, NewtonError

__all__ = ["DENSITY", "mass_matrix", "generalized_mass", "Tie", "TiedStatic", "Newmark",
           "Motion", "newmark_step", "TiedDynamics", "lowest_mode", "field_kinetic_energy",
           "HoldResult", "hold", "HISTORY_COLUMNS"]

# dry granular bulk density [kg/m^3] (sand, 1500-1700): the material point's specimen's
DENSITY = Specimen().density


def mass_matrix(prob: Biaxial, density: float = DENSITY) -> sp.csr_matrix:
    """Consistent mass matrix M_ij = int rho N_i . N_j dA of ``prob``'s vector basis, (ndofs,
    ndofs) [kg/m] (per unit thickness). Integrated with a rule exact for the product of two
    basis functions (intorder 2: 2 x 2 Gauss points on quads, 3 points on triangles), whatever
    rule the specimen's own basis uses for its stresses."""
    if not (math.isfinite(density) and density > 0):
        raise ValueError(f"density = {density!r} is out of range: allowed density > 0 [kg/m^3]")
    basis = Basis(prob.mesh, prob.element, intorder=2)
    rho = float(density)

    @BilinearForm
    def mass(u, v, w):
        return rho * dot(u, v)

    return mass.assemble(basis).tocsr()


def generalized_mass(density: float, width: float, height: float, ratio: float) -> float:
    """m_G [kg/m]: the kinetic energy of the homogeneous motion along the tie is m_G U1'^2 / 2
    (bottom fixed, lateral faces symmetric; docs/burst.md): the material point's
    ``hmodel.burst.Specimen.mass``, rho B H (1/3 + R^2 B^2 / (12 H^2))."""
    return Specimen(width, height, density).mass(ratio)


class Tie:
    """Rigid smooth platens on the four faces of ``prob``, tied to the generalized displacement
    U1 [m] (compression positive) along the path d eps2 = ``ratio`` d eps1, as increments from
    the state the tie starts from (the faces move rigidly, whatever their shape then):

        bottom u_y = 0, top u_y = -U1, left u_x = +U2/2, right u_x = -U2/2,  U2 = R (B/H) U1

    (U2 = B eps2 compression positive: R < 0 widens the specimen). Tangential motion is free on
    every face (smooth platens); the corners take the constraint of each face they lie on.

    Reduced coordinates z = (w, U1): u = u_ref + T z, T = [E | a], E the columns of the ``free``
    dofs (not constrained by a face), ``a`` (ndofs,) the homogeneous mode per unit U1 (the nodal
    values of u_y = -(y - y0)/H, u_x = R B/(2H) (1 - 2 (x - x0)/B)), which meets the tie on the
    faces and is exact in the element space: a^T M a = m_G (``generalized_mass``). The generalized
    force of a nodal force vector f is a . f [N/m]; for the internal force it is, by virtual work,
    B times the volume average of c = s1 + R s2 for any field, and G at equilibrium.
    """

    def __init__(self, prob: Biaxial, ratio: float):
        if not (math.isfinite(ratio) and ratio != 0):
            raise ValueError(f"ratio = {ratio!r} is out of range: allowed a finite R != 0")
        self.prob = prob
        self.ratio = float(ratio)
        p = prob.mesh.p
        x0, x1, y0, y1 = p[0].min(), p[0].max(), p[1].min(), p[1].max()
        B, H = prob.width, prob.height
        tol = 1e-9 * max(B, H)
        nd = np.asarray(prob.basis.nodal_dofs)                  # (2, nnodes): x, y dofs
        a = np.zeros(prob.ndofs)
        a[nd[1]] = -(p[1] - y0) / H
        a[nd[0]] = self.ratio * B / (2.0 * H) * (1.0 - 2.0 * (p[0] - x0) / B)
        self.a = a
        self.left_x = nd[0, np.abs(p[0] - x0) < tol]
        self.right_x = nd[0, np.abs(p[0] - x1) < tol]
        self.bottom_y = nd[1, np.abs(p[1] - y0) < tol]
        self.top_y = nd[1, np.abs(p[1] - y1) < tol]
        self.constrained = np.unique(np.concatenate([self.bottom_y, self.top_y, self.left_x,
                                                     self.right_x]))
        self.free = np.setdiff1d(np.arange(prob.ndofs), self.constrained)
        n = self.free.size
        E = sp.csr_matrix((np.ones(n), (self.free, np.arange(n))), shape=(prob.ndofs, n + 1))
        A = sp.csr_matrix(a[:, None]) @ sp.csr_matrix(([1.0], ([0], [n])), shape=(1, n + 1))
        self.T = (E + A).tocsr()                                # (ndofs, n + 1)
        self.TT = self.T.T.tocsr()
        self.size = n + 1

    def displacement(self, z: np.ndarray) -> np.ndarray:
        """(ndofs,) nodal displacement T z [m] of reduced coordinates z (an increment)."""
        return self.T @ z

    def reduce_vector(self, f: np.ndarray) -> np.ndarray:
        """T^T f: the free dofs' entries and, last, the generalized force a . f [N/m]."""
        return self.TT @ f

    def reduce_matrix(self, K) -> sp.csc_matrix:
        """T^T K T (sparse, csc) of a (ndofs, ndofs) stiffness [Pa] or mass [kg/m]."""
        return (self.TT @ K @ self.T).tocsc()


class TiedStatic:
    """The specimen under the tie with U1 prescribed, in the form ``fem.solver.newton_step`` and
    ``LoadStepper`` use (``free``, ``prescribed``, ``prescribed_values``, no external load on the
    free dofs): the quasi-static proportional strain path, from the state with displacement
    ``u_ref`` (U1 = delta = 0 there)."""

    def __init__(self, tie: Tie, u_ref: np.ndarray):
        prob = tie.prob
        self.tie = tie
        self.u_ref = np.array(u_ref, dtype=float)
        self.material = prob.material
        self.strain = prob.strain
        self.internal_force = prob.internal_force
        self.stiffness = prob.stiffness
        self.height, self.sigma2, self.ndofs = prob.height, prob.sigma2, prob.ndofs
        self.free = tie.free
        self.prescribed = tie.constrained
        self.f_lat = np.zeros(prob.ndofs)       # the platens take the lateral pressure's place

    def prescribed_values(self, delta: float) -> np.ndarray:
        """Values [m] of the constrained dofs for U1 = ``delta`` (order of ``prescribed``)."""
        c = self.prescribed
        return self.u_ref[c] + self.tie.a[c] * delta


class Newmark(NamedTuple):
    """Newmark's scheme: u1 = u0 + dt v0 + dt^2 ((1/2 - beta) a0 + beta a1),
    v1 = v0 + dt ((1 - gamma) a0 + gamma a1). The default, average acceleration (beta 1/4,
    gamma 1/2), has no numerical damping, elongates the period of a linear oscillator as
    omega_num dt = 2 arctan(omega dt / 2), and keeps the discrete energy balance exact:
    E_c(n+1) - E_c(n) = du . (F(n) + F(n+1)) / 2, F = f_ext - f_int - C v."""

    beta: float = 0.25
    gamma: float = 0.5


class Motion(NamedTuple):
    """The state of the reduced system at a time: z, v, a (n,) [m, m/s, m/s^2] (U1 last) and the
    reduced internal force f = T^T f_int (n,) [N/m]."""

    z: np.ndarray
    v: np.ndarray
    a: np.ndarray
    f: np.ndarray


class TiedDynamics:
    """The reduced system of the tied specimen from a committed state (the switch) with
    displacement ``u_ref``: mass M = T^T M T, mass-proportional damping C = ``alpha`` M
    (alpha = 2 zeta omega_1 [1/s]), the external force f(0) + (0, ..., ``dG``) with f(0) the
    reduced internal force of the committed state (``start``; G_switch its last entry, the
    generalized force), the internal force at reduced
    coordinates z from the committed material state (``force``) and Newton's linear solve with
    its tangent (``solve``)."""

    def __init__(self, tie: Tie, mass, u_ref: np.ndarray, dG: float, alpha: float):
        prob = tie.prob
        self.tie, self.prob = tie, prob
        self.mass = mass
        self.M = tie.reduce_matrix(mass)
        self.solver = FreeSolver(tie.free)
        self._mass_key = None
        self.alpha = float(alpha)
        self.dG = float(dG)
        self.u_ref = np.array(u_ref, dtype=float)
        self.f_ref = prob.sigma2 * prob.height          # Newton's scale, as fem.solver's [N/m]
        self.f_ext = None

    def start(self) -> np.ndarray:
        """At u_ref with the committed material: returns the reduced internal force f(0) = T^T
        f_int there, as ``force`` gives it (the material's trial of a zero increment), and sets
        f_ext = f(0) + (0, ..., dG): G_switch = f(0)'s last entry, and the switch is an exact
        equilibrium of the discrete system (its static Newton residual, <= rtol sigma2 H on the
        free dofs, is kept as a load): with dG = 0 nothing moves, E_c = 0."""
        self._eps_committed = self.prob.strain(self.u_ref)
        f0, _ = self.force(np.zeros(self.tie.size))
        self.f_ext = f0.copy()
        self.f_ext[-1] += self.dG
        return f0

    def force(self, z: np.ndarray):
        """(T^T f_int, trial) at reduced coordinates z (the total since u_ref): the material
        updated from its committed state by the strain of u_ref + T z less the committed strain
        (nothing committed)."""
        prob = self.prob
        eps = prob.strain(self.u_ref + self.tie.displacement(z))
        trial = prob.material.trial(eps - self._eps_committed)
        return self.tie.reduce_vector(prob.internal_force(trial.sigma)), trial

    def _mass_on(self, K) -> np.ndarray:
        """The mass's entries at K's stored entries (K.data's order): K + c M keeps K's one
        pattern (a sum by scipy drops the entries that cancel, and a new pattern costs the
        linear solver its kept column order)."""
        key = self._mass_key
        if key is None or not (np.array_equal(key[0], K.indptr)
                               and np.array_equal(key[1], K.indices)):
            rows = np.repeat(np.arange(K.shape[0]), np.diff(K.indptr))
            mk = np.asarray(self.mass[rows, K.indices]).ravel()
            if not math.isclose(float(abs(mk).sum()), float(abs(self.mass).sum()), rel_tol=1e-12):
                raise ValueError("the mass matrix has entries outside the stiffness's pattern")
            self._mass_key = key = (K.indptr.copy(), K.indices.copy(), mk)
        return key[2]

    def solve(self, trial, mass_coeff: float, r: np.ndarray) -> np.ndarray:
        """S^{-1} r for the reduced S = T^T (K + mass_coeff M) T, K the tangent of ``trial``:
        bordered, so that the one sparse LU is of the free dofs' block S_ff = S[free][:, free]
        (``FreeSolver``: the static solver, its column order kept between calls), without the
        dense row and column of U1 (the homogeneous mode touches every dof):

            [[S_ff, b], [c^T, d]] (x, U1) = (r_f, r_1),  b = (S a)_f, c = (S^T a)_f, d = a.S a
            U1 = (r_1 - c . S_ff^-1 r_f) / (d - c . S_ff^-1 b),  x = S_ff^-1 (r_f - b U1)."""
        K = self.prob.stiffness(trial.D)
        S = sp.csr_matrix((K.data + mass_coeff * self._mass_on(K), K.indices, K.indptr),
                          shape=K.shape)
        a, free = self.tie.a, self.tie.free
        Sa, aS = S @ a, S.T @ a
        x = self.solver.solve(S, np.column_stack([r[:-1], Sa[free]]))
        den = float(a @ Sa - aS[free] @ x[:, 1])
        if not (math.isfinite(den) and den != 0.0):
            raise NewtonError("singular dynamic tangent (generalized dof)")
        u1 = (r[-1] - aS[free] @ x[:, 0]) / den
        return np.append(x[:, 0] - x[:, 1] * u1, u1)

    def commit(self, z: np.ndarray, trial) -> None:
        """Commit the material's ``trial`` of the converged step ending at z."""
        self.prob.material.commit(trial)
        self._eps_committed = self.prob.strain(self.u_ref + self.tie.displacement(z))


def newmark_step(system: TiedDynamics, m: Motion, dt: float, scheme: Newmark = Newmark(),
                 rtol: float = 1e-10, max_iter: int = 25):
    """One time step of ``scheme`` from motion ``m``: Newton on the increment du of the reduced
    coordinates with the consistent tangent K + gamma/(beta dt) C + M/(beta dt^2), until
    |M a1 + C v1 + f(z1) - f_ext| <= rtol f_ref. Returns (Motion at t + dt, trial, iterations,
    normalized residual). Nothing is committed. Raises NewtonError."""
    beta, gamma = scheme
    cm = 1.0 / (beta * dt * dt)
    cv = gamma / (beta * dt)
    M, alpha = system.M, system.alpha
    du = dt * m.v + 0.5 * dt * dt * m.a            # constant-acceleration predictor
    base = dt * m.v + dt * dt * (0.5 - beta) * m.a
    for k in range(max_iter + 1):
        a1 = cm * (du - base)
        v1 = m.v + dt * ((1.0 - gamma) * m.a + gamma * a1)
        try:
            f1, trial = system.force(m.z + du)
        except ValueError as e:
            raise NewtonError(f"material update failed: {e}") from None
        r = M @ (a1 + alpha * v1) + f1 - system.f_ext
        rn = float(np.linalg.norm(r)) / system.f_ref
        if not math.isfinite(rn):
            raise NewtonError("non-finite residual")
        if rn <= rtol:
            return Motion(m.z + du, v1, a1, f1), trial, k, rn
        if k == max_iter:
            break
        du = du - system.solve(trial, cm + cv * alpha, r)
    raise NewtonError(f"time step did not converge in {max_iter} Newton iterations (residual "
                      f"{rn:.3e} > rtol = {rtol:.1e} x sigma2 x height)")


def lowest_mode(K, M):
    """(omega_1 [rad/s], mode (n,)) of the lowest generalized eigenvalue of (K, M), K the elastic
    tangent stiffness and M the mass, both reduced (n, n). Dense below 300 unknowns, else ARPACK
    in shift-invert mode about 0 from a seeded start vector. Raises ValueError when the lowest
    eigenvalue is not real and positive (no elastic oscillation to take a period from)."""
    n = K.shape[0]
    if n < 300:
        w, V = scipy.linalg.eig(K.toarray(), M.toarray())
        ok = np.isfinite(w)
        w, V = w[ok], V[:, ok]
    else:
        # a seeded start vector: ARPACK's default is random, and T1 sets dt (reproducible runs)
        v0 = np.random.default_rng(0).standard_normal(n)
        w, V = spla.eigs(K, k=3, M=M, sigma=0.0, which="LM", v0=v0)
    k = int(np.argmin(np.abs(w)))
    lam, mode = w[k], V[:, k]
    if abs(lam.imag) > 1e-8 * abs(lam.real) or lam.real <= 0:
        raise ValueError(f"the lowest elastic eigenvalue {lam:.6g} is not real and positive: no "
                         "elastic period at this state")
    mode = np.real(mode)
    return math.sqrt(lam.real), mode / np.max(np.abs(mode))


def field_kinetic_energy(basis: Basis, v: np.ndarray, density: float) -> float:
    """rho/2 int |v_h|^2 dA [J/m] (per unit thickness) of the nodal velocity ``v`` (ndofs,)
    [m/s], v_h interpolated at the quadrature points of ``basis`` (the specimen's vector basis
    with a rule exact for |v_h|^2: intorder 2). The field integrated with the density, not
    v.M v / 2 with an assembled mass matrix: the kinetic energy of the energy check
    (``hmodel.burst_rule.EnergyCheck``), which a wrong mass in the integrator must not share."""
    vq = np.asarray(basis.interpolate(v))                           # (2, nel, nqp)
    return 0.5 * float(density) * float(np.sum(np.sum(vq * vq, axis=0) * np.asarray(basis.dx)))


HISTORY_COLUMNS = ["step", "t", "eps1", "eps2", "c", "G", "U1", "ke", "w_ext", "w_int",
                   "damping", "w2_ext", "w2_int", "newton_work", "newton_work_sum", "ke_mid",
                   "w2_int_stress", "damping_mid", "energy_check", "u_norm", "newton_iters"]


class HoldResult(NamedTuple):
    """A run at a held force: outcome (``hmodel.burst_rule.OUTCOMES``: 'equilibrium',
    'failure', 'undecided' by the rule, 'not_converged' when a time step converged at no
    substep), the history (HISTORY_COLUMNS -> (steps + 1,) arrays, row 0 the switch), the final
    displacement and velocity (ndofs,) [m, m/s] (from the switch), T1 [s], dt [s], seconds;
    cut_steps: {step: halvings} of the time steps run in substeps; failure_reason: what did not
    converge when the outcome is 'not_converged' ('' for every other outcome)."""

    outcome: str
    history: dict
    u: np.ndarray
    v: np.ndarray
    t1: float
    dt: float
    seconds: float
    cut_steps: dict = {}
    failure_reason: str = ""


def hold(tie: Tie, mass, u_ref: np.ndarray, dG: float, t1: float, steps_per_period: int = 20,
         damping_ratio: float = 0.05, rule: BurstRule = BurstRule(), eps_ref=(0.0, 0.0),
         scheme: Newmark = Newmark(), rtol: float = 1e-10, max_iter: int = 25,
         on_step=None, max_steps: int | None = None, density: float = DENSITY) -> HoldResult:
    """From the committed material state of ``tie.prob`` at displacement ``u_ref``, at rest,
    hold the generalized force at G_switch + ``dG`` [N/m] (G_switch = a . f_int there) and
    integrate until ``decide`` gives an outcome (window rule.window_periods x T1) or the cap
    (rule.max_periods x T1, or ``max_steps``): 'undecided'; a time step that converges at no
    substep (down to dt / 2**MAX_CUTS) ends the run as 'not_converged', what failed in
    ``failure_reason`` (the integrator stopped, not the specimen: never a burst).

    mass : the (ndofs, ndofs) mass matrix the integrator uses [kg/m]; density [kg/m^3] : the
    specimen's, for the energy check's kinetic energy (the velocity field integrated with it,
    not with ``mass``). t1 : the lowest elastic period T1 [s] (``lowest_mode``); dt = T1 /
    steps_per_period; the damping C = 2 zeta (2 pi / T1) M, zeta = ``damping_ratio``. eps_ref :
    (eps1, eps2) of the switch (compression positive) for the recorded strains.
    ``on_step(step, motion, system, row)`` at the switch (step 0) and after each step, ``row``
    the step's history (a dict of HISTORY_COLUMNS), e.g. to write it and the fields as the run
    goes. The material state is committed step by step (the specimen ends in the run's last
    state).

    Every step records (HISTORY_COLUMNS): t [s]; eps1, eps2; c = G/B [Pa]; G = a . f_int [N/m];
    U1 [m]; the integrator's energies [J/m]: ke = v.M v / 2, w_ext, w_int, damping the
    trapezoidal works of f_ext, f_int and C v over dz (a held force: w_ext = G_ext U1, up to the
    switch's Newton residual kept in f_ext, see ``TiedDynamics.start``), w2_ext = sum dz .
    (f_ext - f_ext(0)) = dG U1, w2_int = sum dz . ((f(n) + f(n+1))/2 - f(0)), f_ext(0) = f(0)
    the switch's; newton_work, Newmark's balance of the step |dE_c - (dW_ext - dW_int - dD)|
    over the largest second-order energy so far, max(E_c, |W2_ext|, |W2_int|, D) (the
    first-order work of the prestress, G_switch U1, is orders larger and would hide any
    residual): for the average-acceleration rule it equals |dz . (r(n) + r(n+1)) / 2| / scale,
    r the Newton residual of the equation of motion, for any symmetric M and any f_int: the work
    of the Newton residual, nothing about the mass or the forces; newton_work_sum, |E_c -
    (W2_ext - W2_int - D)| on the same scale, the same residuals' work summed since the switch
    (f_ext(0) = f(0) cancels); the energy check that the scheme cannot satisfy by itself
    (``hmodel.burst_rule.EnergyCheck``): ke_mid, E_c at the step's midpoint of the velocity
    field T dz / dt integrated with ``density`` (``field_kinetic_energy``), w2_int_stress, W2_int
    from the quadrature points' stresses and the material's own strain increments
    (``MaterialField.stress_work``, weights dx), damping_mid, the damping's work 2 alpha ke_mid
    dt, and energy_check, ke_mid - the mean of W2_ext - w2_int_stress - damping_mid at the
    step's ends [J/m] (O(dt^2) on a healthy run; ``check_columns`` makes it relative); u_norm =
    |u - u_ref| [m]; Newton iterations.
    """
    if not (isinstance(steps_per_period, (int, np.integer)) and steps_per_period >= 10):
        raise ValueError(f"steps_per_period = {steps_per_period!r} is out of range: allowed an "
                         "integer >= 10 (a time step must resolve the lowest period)")
    if not (math.isfinite(damping_ratio) and 0 <= damping_ratio < 1):
        raise ValueError(f"damping_ratio = {damping_ratio!r} is out of range: allowed "
                         "0 <= zeta < 1")
    if not (math.isfinite(dG) and dG >= 0):
        raise ValueError(f"dG = {dG!r} is out of range: allowed dG >= 0 [N/m]")
    if not (math.isfinite(density) and density > 0):
        raise ValueError(f"density = {density!r} is out of range: allowed density > 0 [kg/m^3]")
    t0 = time.perf_counter()
    prob = tie.prob
    B, H, R = prob.width, prob.height, tie.ratio
    dt = t1 / steps_per_period
    alpha = 2.0 * damping_ratio * 2.0 * math.pi / t1
    n_cap = int(math.ceil(rule.max_periods * steps_per_period))
    if max_steps is not None:
        n_cap = min(n_cap, int(max_steps))
    window = rule.window_periods * t1
    system = TiedDynamics(tie, mass, u_ref, dG, alpha)
    f0 = system.start()
    g_sw = float(f0[-1])
    M = system.M
    n = tie.size
    # the energy check's own ingredients: the material's states at the switch, the quadrature
    # weights of its points, the basis of the velocity field (a rule exact for |v_h|^2)
    ref_states = list(prob.material.states)
    weights = prob.dx.reshape(-1)
    field_basis = Basis(prob.mesh, prob.element, intorder=2)
    check = EnergyCheck(alpha)
    # at rest: M a0 = f_ext - f(0) = (0, ..., dG)
    z0 = np.zeros(n)
    a0 = spla.splu(M.tocsc()).solve(system.f_ext - f0)
    m = Motion(z0, np.zeros(n), a0, f0)
    f_ext0 = f0                                   # the switch: f_ext(0) = f(0)
    h = {k: np.zeros(n_cap + 1) for k in HISTORY_COLUMNS}
    h["eps1"][0], h["eps2"][0] = eps_ref
    h["c"][0], h["G"][0] = g_sw / B, g_sw
    scale = 0.0
    outcome = None
    k = 0

    def row(k):
        return {key: int(v[k]) if key in ("step", "newton_iters") else float(v[k])
                for key, v in h.items()}

    if on_step is not None:
        on_step(0, m, system, row(0))
    cut_steps, why = {}, ""
    floor = 0.5 ** MAX_CUTS
    while k < n_cap:
        # the time step, whole or (its Newton failing) in substeps: halves, growing back x2 after
        # each success, down to dt / 2**MAX_CUTS; each substep Newmark's own, committed, so the
        # step's works are the sums of its substeps' and the balance stays exact
        frac, hs, depth, iters = 0.0, 1.0, 0, 0
        d_ext = d_int = d_damp = d_w2e = d_f0 = d_wis = 0.0
        worst = ke_mid = 0.0
        while frac < 1.0:
            hs = min(hs, 1.0 - frac)
            try:
                m1, trial, it, _ = newmark_step(system, m, hs * dt, scheme, rtol, max_iter)
            except NewtonError as e:
                if hs * 0.5 >= floor:
                    hs *= 0.5
                    depth += 1
                    continue
                why = (f"time step {k + 1} did not converge even in substeps of dt / "
                       f"2**{MAX_CUTS} ({e})")
                break
            dz = m1.z - m.z
            # the energy check, before the commit (the committed states are the step's start)
            dwis = prob.material.stress_work(trial.states, ref_states, weights)
            ke_mid = field_kinetic_energy(field_basis, tie.displacement(dz) / (hs * dt),
                                          density)
            res = check.step(hs * dt, ke_mid, float(dz @ (system.f_ext - f_ext0)), dwis)
            worst = res if abs(res) > abs(worst) else worst
            system.commit(m1.z, trial)
            d_ext += float(dz @ system.f_ext)
            d_int += 0.5 * float(dz @ (m.f + m1.f))
            d_damp += 0.5 * alpha * float(dz @ (M @ (m.v + m1.v)))
            d_w2e += float(dz @ (system.f_ext - f_ext0))
            d_f0 += float(dz @ f0)
            d_wis += dwis
            iters += it
            m = m1
            frac += hs
            hs *= 2.0
        if depth or why:
            cut_steps[k + 1] = MAX_CUTS if why else depth
        if why and frac == 0.0:
            outcome = "not_converged"
            break
        ke1 = 0.5 * float(m.v @ (M @ m.v))
        k += 1
        h["step"][k], h["t"][k] = k, (k - 1 + frac) * dt
        U1 = float(m.z[-1])
        h["U1"][k] = U1
        h["eps1"][k] = eps_ref[0] + U1 / H
        h["eps2"][k] = eps_ref[1] + R * U1 / H
        h["G"][k] = float(m.f[-1])
        h["c"][k] = h["G"][k] / B
        h["ke"][k] = ke1
        h["w_ext"][k] = h["w_ext"][k - 1] + d_ext
        h["w_int"][k] = h["w_int"][k - 1] + d_int
        h["damping"][k] = h["damping"][k - 1] + d_damp
        h["w2_ext"][k] = h["w2_ext"][k - 1] + d_w2e
        h["w2_int"][k] = h["w2_int"][k - 1] + d_int - d_f0
        scale = max(scale, ke1, abs(h["w2_ext"][k]), abs(h["w2_int"][k]), h["damping"][k])
        res = (ke1 - h["ke"][k - 1]) - (d_ext - d_int - d_damp)
        eq1 = ke1 - (h["w2_ext"][k] - h["w2_int"][k] - h["damping"][k])
        h["newton_work"][k] = abs(res) / scale if scale > 0 else 0.0
        h["newton_work_sum"][k] = abs(eq1) / scale if scale > 0 else 0.0
        h["ke_mid"][k] = ke_mid
        h["w2_int_stress"][k] = h["w2_int_stress"][k - 1] + d_wis
        h["damping_mid"][k] = check.damping
        h["energy_check"][k] = worst
        h["u_norm"][k] = float(np.linalg.norm(tie.displacement(m.z)))
        h["newton_iters"][k] = iters
        if on_step is not None:
            on_step(k, m, system, row(k))
        if why:
            outcome = "not_converged"
            break
        s = slice(0, k + 1)
        outcome = decide(h["t"][s], h["ke"][s], h["w2_ext"][s], h["eps1"][s], window, rule)
        if outcome is not None:
            break
    history = {key: v[:k + 1].copy() for key, v in h.items()}
    return HoldResult(outcome or "undecided", history, tie.displacement(m.z),
                      tie.displacement(m.v), t1, dt, time.perf_counter() - t0, cut_steps, why)
