"""The FE's fast paths give the bits of the plain expressions they replace: the gathered free
block of K and its symmetric part, the Newton solve with its column order found once, the local
W2 and Rice kernels against one-direction-at-a-time references."""
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem.indicators import GlobalCheck, _rice_kernel, _w2_min_kernel, _w2_one, fibonacci_sphere
from fem.mesh import rectangle
from fem.problem import Biaxial, Imperfection, PatternGather
from fem.solver import FreeSolver, NewtonError


def _same(A, B):
    return (type(A) is type(B) and A.shape == B.shape
            and all(getattr(A, k).dtype == getattr(B, k).dtype
                    and getattr(A, k).tobytes() == getattr(B, k).tobytes()
                    for k in ("data", "indices", "indptr")))


@pytest.fixture(scope="module")
def stiffnesses(params36):
    """A weak-spot specimen's stiffness matrices at the tangents of a few random strains (the
    same sparsity pattern, different values, some of them indefinite)."""
    prob = Biaxial(rectangle(0.05, 0.1, 3, 6), params36,
                   imperfection=Imperfection("spot", size=0.3, phi_g=17.0))
    rng = np.random.default_rng(3)
    Ks = []
    for k in range(5):
        de = np.zeros((2, 2, prob.npts))
        de[1, 1] = -2e-3 * (k + 1) * (1 + 0.2 * rng.standard_normal(prob.npts))
        de[0, 0] = 0.6e-3 * (k + 1)
        Ks.append(prob.stiffness(prob.material.trial(de).D))
    return prob, Ks


def test_pattern_gather_is_the_expression(stiffnesses):
    prob, Ks = stiffnesses
    free = prob.free
    perm = np.random.default_rng(0).permutation(free.size)
    for f in (lambda K: K[free][:, free].tocsc(), lambda K: K[free][:, free].tocsc()[:, perm].tocsc(),
              lambda K: K.T.tocsr()):
        g = PatternGather(f)
        for K in Ks:
            assert _same(g(K), f(K))
    # a new pattern is found again
    g = PatternGather(lambda K: K[free][:, free].tocsc())
    g(Ks[0])
    K2 = Ks[1][:-1][:, :-1].tocsr()
    assert _same(g(K2), K2[free[free < K2.shape[0]]][:, free[free < K2.shape[0]]].tocsc())


@pytest.mark.parametrize("f", [lambda K: (K + K.T).tocsr(), lambda K: 2.0 * K,
                               lambda K: (K + sp.identity(K.shape[0], format="csr")).tocsr()])
def test_pattern_gather_refuses_what_is_not_a_restructuring(stiffnesses, f):
    """Sums, scalings, shifted values: not one entry of K per entry of f(K)."""
    prob, Ks = stiffnesses
    with pytest.raises(ValueError, match="restructuring"):
        PatternGather(f)(Ks[0])


def test_global_check_free_block_and_symmetric_part(stiffnesses):
    prob, Ks = stiffnesses
    check = GlobalCheck(prob)
    free = prob.free
    for K in Ks:
        check(K, want_modes=False)
        Kd = K[free][:, free].tocsc()
        assert _same(check._kd(K), Kd)
        assert _same(check._sym_part(check._kd(K)), (0.5 * (Kd + Kd.T)).tocsc())
    # an entry with a_ij + a_ji = 0: scipy's sum drops it, so does the symmetric part
    K = Ks[0].copy()
    Kd = K[free][:, free].tocsc()
    i, j = 0, int(Kd.indices[Kd.indptr[0] + 1])
    K[free[i], free[j]] = -K[free[j], free[i]]
    Kd = K[free][:, free].tocsc()
    S = check._sym_part(check._kd(K))
    assert _same(S, (0.5 * (Kd + Kd.T)).tocsc()) and S.nnz < Kd.nnz


def test_free_solver_gives_the_plain_splu_bits(stiffnesses):
    prob, Ks = stiffnesses
    free = prob.free
    solver = FreeSolver(free)
    rng = np.random.default_rng(1)
    for K in Ks + Ks[::-1]:
        b = rng.standard_normal(free.size)
        x = spla.splu(K[free][:, free].tocsc()).solve(b)
        assert solver.solve(K, b).tobytes() == x.tobytes()
    assert solver._ordered is not None          # the later solves took the ordered route


def test_free_solver_singular_is_a_newton_error(stiffnesses):
    prob, Ks = stiffnesses
    solver = FreeSolver(prob.free)
    solver.solve(Ks[0], np.ones(prob.free.size))
    Z = Ks[0].copy()
    Z.data[:] = 0.0
    for _ in range(2):                          # the plain route, then the ordered one
        with pytest.raises(NewtonError, match="singular"):
            solver.solve(Z, np.ones(prob.free.size))


def _w2_reference(M, X, spacing):
    """The pattern search one direction at a time (the kernel's algorithm written plainly)."""
    out = np.empty(M.shape[0])
    ring = 2.0 * np.pi * np.arange(12) / 12.0
    cr, sr = np.cos(ring), np.sin(ring)
    for p, m in enumerate(M):
        d = X @ m.T
        num = np.sum(X * d, axis=1)
        vals = num * np.abs(num) / np.maximum(np.sum(d * d, axis=1), 1e-300)
        nb = int(np.argmin(vals))
        bx, by, bz = X[nb]
        best = _w2_one.py_func(m, bx, by, bz)
        h = spacing
        for _ in range(4):
            t1 = np.array([-by, bx, 0.0]) if abs(bz) < 0.9 else np.array([0.0, bz, -by])
            nt = np.sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2])
            t1x, t1y, t1z = t1[0] / nt, t1[1] / nt, t1[2] / nt
            t2x, t2y, t2z = by * t1z - bz * t1y, bz * t1x - bx * t1z, bx * t1y - by * t1x
            cx, cy, cz = bx, by, bz
            for r in range(1, 4):
                rad = h * r / 3.0
                for k in range(12):
                    x = cx + rad * (cr[k] * t1x + sr[k] * t2x)
                    y = cy + rad * (cr[k] * t1y + sr[k] * t2y)
                    z = cz + rad * (cr[k] * t1z + sr[k] * t2z)
                    v = _w2_one.py_func(m, x, y, z)
                    if v < best:
                        nn = np.sqrt(x * x + y * y + z * z)
                        best, bx, by, bz = v, x / nn, y / nn, z / nn
            h /= 3.0
        out[p] = best
    return out


def test_w2_kernel_is_the_one_at_a_time_search():
    """Bit for bit: the kernel evaluates a round's 36 directions in one loop and keeps the first
    below the best; the reference compares them one by one (numpy's argmin is the first minimum
    too; the sampled values are the kernel's expression, elementwise)."""
    rng = np.random.default_rng(11)
    M = rng.normal(size=(40, 3, 3))
    M[1] = M[1] + M[1].T + 3 * np.eye(3)                 # positive definite: W2 > 0 everywhere
    M[2] = 0.0                                           # M x = 0
    X = fibonacci_sphere(120)
    spacing = np.sqrt(2.0 * np.pi / 120)
    assert _w2_min_kernel(M, X, spacing).tobytes() == _w2_reference(M, X, spacing).tobytes()


def test_rice_kernel_is_the_one_at_a_time_minimum():
    rng = np.random.default_rng(5)
    D = rng.normal(size=(30, 2, 2, 2, 2))
    D[3] = 0.0
    th = np.linspace(0.0, np.pi, 37, endpoint=False)
    c, s = np.cos(th), np.sin(th)
    vals, idx = _rice_kernel(D.reshape(30, 16), c, s)
    for p in range(30):
        d = D[p]
        best, kb = 1e300, 0
        for a in range(th.size):
            n = (c[a], s[a])
            A = [[n[0] * n[0] * d[0, j, k, 0] + n[0] * n[1] * d[0, j, k, 1]
                  + n[1] * n[0] * d[1, j, k, 0] + n[1] * n[1] * d[1, j, k, 1]
                  for k in range(2)] for j in range(2)]
            v = A[0][0] * A[1][1] - A[0][1] * A[1][0]
            if v < best:
                best, kb = v, a
        assert vals[p] == best and idx[p] == kb


@pytest.mark.parametrize("kind", ["quad", "tri"])
def test_element_matrices_are_numpys_matmul(params36, kind):
    """The assembly kernel against the numpy expression it replaced, to the rounding of the
    products (bit for bit with this machine's OpenBLAS, which accumulates as the kernel does; a
    BLAS that accumulates in another order differs by a few ulps, which this bound allows: the
    kernel's K then does not depend on the BLAS), and the csr K against the coo route."""
    from fem.problem import _element_matrices
    prob = Biaxial(rectangle(0.05, 0.1, 3, 6, kind), params36)
    rng = np.random.default_rng(2)
    D = rng.normal(size=(2, 2, 2, 2, prob.npts)) * 1e6
    D[..., 0] = 0.0
    D[0, 0, 0, 0, 1] = -0.0
    Dp = np.ascontiguousarray(D.reshape(4, 4, prob.npts).transpose(2, 0, 1))

    def numpy_route(B, Dq):
        BD = np.matmul(B, Dq) * prob._wp[:, None, None]
        Ke = np.matmul(BD, B.transpose(0, 2, 1))
        return Ke.reshape(prob.nel, prob.nqp, prob.nbf * prob.nbf).sum(axis=1)
    Ke = numpy_route(prob._Bp, Dp)
    E = _element_matrices(prob._Bp, Dp, prob._wp, prob.nqp)
    # each entry: sums of 4 + 4 products per point, nqp points: 16 (nqp + 1) eps |terms| bounds
    # the rounding of both routes together
    bound = 16 * (prob.nqp + 1) * np.finfo(float).eps * numpy_route(np.abs(prob._Bp), np.abs(Dp))
    assert np.all(np.abs(E - Ke) <= bound)
    assert np.any(E != 0)
    K = prob.stiffness(D)
    K0 = sp.coo_matrix((E.ravel(), (prob._rows, prob._cols)), shape=K.shape).tocsr()
    assert _same(K, K0)
