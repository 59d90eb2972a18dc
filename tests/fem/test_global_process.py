"""The global check in a process of its own (``GlobalCheckProcess``, the default where Numba has
more than one thread) gives the run of the check in process: every row, field and mode to the
bit; an error in the child reaches the caller; an interrupted run leaves no child behind."""
import multiprocessing

import meshio
import numba
import numpy as np
import pytest

from fem.biaxial import BiaxialConfig, run_biaxial
from fem.indicators import GlobalCheck, GlobalCheckProcess
from fem.output import MODE_FIELDS, read_curve

from .conftest import D_EPS1, N_DIR

pytestmark = pytest.mark.skipif(
    "fork" not in multiprocessing.get_all_start_methods() or numba.config.NUMBA_NUM_THREADS < 2,
    reason="the check runs in process here (no fork, or one Numba thread)")


def _fields(path):
    with meshio.xdmf.TimeSeriesReader(path) as r:
        r.read_points_cells()
        return [r.read_data(k) for k in range(r.num_steps)]


def test_rows_fields_and_modes_are_the_in_process_ones(tmp_path, monkeypatch):
    started = []
    start = GlobalCheckProcess.start.__func__

    def spy(cls, problem, seed=0):
        started.append(start(cls, problem, seed))
        return started[-1]
    monkeypatch.setattr(GlobalCheckProcess, "start", classmethod(spy))
    # past the peak: lam_min(K_s) <= 0 and det K_f changes sign, so the modes are written
    kw = dict(nx=2, ny=4, n_dir=N_DIR, d_eps1=D_EPS1, eps1_max=0.03, n_sphere=100,
              mp_reference=False)
    a = run_biaxial(BiaxialConfig(**kw), tmp_path / "child")
    assert len(started) == 1 and started[0] is not None       # the child did the checks
    b = run_biaxial(BiaxialConfig(**kw, global_process=False), tmp_path / "here")
    assert len(started) == 1
    ca, cb = read_curve(tmp_path / "child" / "curve.csv"), read_curve(tmp_path / "here" / "curve.csv")
    assert ca.keys() == cb.keys()
    for k in ca:
        if k != "time_s":
            assert np.array_equal(ca[k], cb[k], equal_nan=True), k
    for k in a.curve:
        if k != "time_s":
            assert np.array_equal(a.curve[k], b.curve[k], equal_nan=True), k
    assert a.events == b.events and "det_k_f" in a.events and "lam_min_ks" in a.events
    fa, fb = _fields(tmp_path / "child" / "fields.xdmf"), _fields(tmp_path / "here" / "fields.xdmf")
    assert len(fa) == len(fb) == len(ca["step"])
    fired = set()
    for (ta, pa, da), (tb, pb, db) in zip(fa, fb):
        assert ta == tb and pa.keys() == pb.keys() and da.keys() == db.keys()
        for k in pa:
            assert np.array_equal(pa[k], pb[k]), k
            if k in MODE_FIELDS and np.any(pa[k]):
                fired.add(k)
        for k in da:
            assert np.array_equal(da[k][0], db[k][0]), k
    # (det K of the displacement-controlled platen keeps its sign to 3 % on this specimen)
    assert fired >= {"mode_ks", "mode_ks_f", "mode_detk_f"}
    for name in ("mode_ks.png", "mode_ks_f.png"):
        assert (tmp_path / "child" / name).exists() and (tmp_path / "here" / name).exists()


def test_an_error_in_the_child_reaches_the_caller_and_the_child_ends(monkeypatch):
    from fem.biaxial import BiaxialConfig, build_problem

    def boom(self, K, want_modes):
        raise ValueError("a failure inside the check")
    monkeypatch.setattr(GlobalCheck, "_check", boom)      # before the fork: the child has it
    prob = build_problem(BiaxialConfig(nx=1, ny=2, n_dir=16))
    check = GlobalCheckProcess.start(prob)
    try:
        check.submit(prob.stiffness(prob.material.trial(np.zeros((2, 2, prob.npts))).D))
        with pytest.raises(ValueError, match="a failure inside the check"):
            check.result()
    finally:
        check.close()
    assert not [p for p in multiprocessing.active_children() if p.name == "fem-global-check"]


@pytest.mark.parametrize("rows", [1, 3])
def test_an_interrupt_with_a_check_in_flight_leaves_the_rows_and_no_child(tmp_path, rows, capfd,
                                                                          monkeypatch):
    """Ctrl-C while the child checks step ``rows`` (the run is in that step's local
    indicators): the rows before it are written whole (curve.csv and fields.xdmf alike), the
    child ends with the run, and nothing is printed."""
    import fem.biaxial as fb
    calls = []
    local = fb.local_indicators

    def interrupted(*a, **kw):
        calls.append(1)
        if len(calls) == rows + 1:
            raise KeyboardInterrupt
        return local(*a, **kw)
    monkeypatch.setattr(fb, "local_indicators", interrupted)
    cfg = BiaxialConfig(nx=1, ny=2, n_dir=16, eps1_max=0.01, d_eps1=1e-3, n_sphere=20,
                        mp_reference=False)
    with pytest.raises(KeyboardInterrupt):
        run_biaxial(cfg, tmp_path)
    c = read_curve(tmp_path / "curve.csv")
    assert np.array_equal(c["step"], np.arange(rows))
    assert len(_fields(tmp_path / "fields.xdmf")) == rows
    assert not [p for p in multiprocessing.active_children() if p.name == "fem-global-check"]
    assert capfd.readouterr().err == ""


def test_a_new_sparsity_pattern_goes_whole_and_gives_the_in_process_rows():
    """The shared buffer holds K.data of the first stiffness's pattern; a stiffness of another
    pattern (here the same matrix with explicit zeros stored) goes through the pipe whole. The
    rows are those of one GlobalCheck in process fed the same sequence."""
    from fem.biaxial import build_problem
    prob = build_problem(BiaxialConfig(nx=2, ny=4, n_dir=16))
    D = prob.material.trial(np.zeros((2, 2, prob.npts))).D
    K = prob.stiffness(D).tocsr()
    K2 = K.tolil()
    K2[0, prob.ndofs - 1] = 1.0           # an entry outside the pattern, then its value zeroed:
    K2 = K2.tocsr()                       # stored, so the pattern differs, the matrix does not
    K2.data[(K2.indices == prob.ndofs - 1) & (np.repeat(np.arange(prob.ndofs),
                                                         np.diff(K2.indptr)) == 0)] = 0.0
    assert K2.nnz == K.nnz + 1 and (K2 - K).count_nonzero() == 0
    here = GlobalCheck(prob)
    child = GlobalCheckProcess.start(prob)
    try:
        for M in (K, K2, 1.5 * K, K2):
            child.submit(M)
            got, modes = child.result()
            want, want_modes = here(M)
            assert got == want
            assert modes.keys() == want_modes.keys()
            for k in modes:
                assert (modes[k] is None and want_modes[k] is None) \
                    or np.array_equal(modes[k], want_modes[k])
    finally:
        child.close()
