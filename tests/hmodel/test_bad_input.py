"""Bad input is one line ``error: ...`` naming the option, exit code 2, before anything is
computed or written; states that do not belong to the parameters are refused; outputs get the
ordinary file mode; an interrupted command says where it stopped (issue 10, sections 2-4)."""
import io
import os
import signal
from types import SimpleNamespace

import numpy as np
import pytest

import hmodel.cli as cli
from hmodel import HParams, broadcast_state, update
from hmodel.driver import drained_biaxial, isotropic_state, run_path
from hmodel.experiment import DOMAIN_COLUMNS, domain_point
from common.io import write_csv
from hmodel.material import take_points
from hmodel.params import ParamError
from common.options import announce_compilation
from tests._interrupt import HANG_S, interrupt_after


def _refused(capsys, argv, *needles):
    assert cli.main(argv) == 2
    cap = capsys.readouterr()
    err = cap.err.strip()
    assert err.startswith("error: ") and "\n" not in err, err
    assert "Traceback" not in err and "HParams" not in err, err
    for n in needles:
        assert n in err, (n, err)
    return err


@pytest.mark.parametrize("argv,needles", [
    (["biaxial", "--d-eps1", "1e-13"], ["--d-eps1", "GB of memory"]),
    (["biaxial", "--eps1-max", "2"], ["--eps1-max", "0 < value < 0.5"]),
    (["biaxial", "--d-eps1", "0.1", "--eps1-max", "0.05"], ["--d-eps1", "0.05"]),
    (["probes", "--d-eps1", "1e-13"], ["--d-eps1", "GB of memory"]),
    (["probes", "--stress-step", "0"], ["--stress-step", "0 < value <= 360"]),
    (["probes", "--eta-a", "nan"], ["--eta-a", "0 < value < 2"]),
    (["probes", "--eta-a", "-1"], ["--eta-a"]),
    (["probes", "--stress-norm", "0"], ["--stress-norm", "0 < value"]),
    (["probes", "--n-probes", "4"], ["--n-probes", ">= 8"]),
    (["probes", "--n-probes", "100000000"], ["--n-probes", "GB of memory"]),
    (["probes", "--phi-g", "95"], ["--phi-g", "0 < phi_g < 90"]),
    (["biaxial", "--kn", "nan"], ["--kn", "finite"]),
    (["biaxial", "--sigma2", "-1"], ["--sigma2"]),
    (["domain", "--sigma2", "100e3,0"], ["--sigma2", "0 < value"]),
    (["domain", "--sigma2", ","], ["--sigma2"]),
    (["domain", "--workers", "0"], ["--workers", "1 <= value"]),
    (["domain", "--workers", "-2"], ["--workers", "1 <= value"]),
    (["domain", "--n-dir", "8.5"], ["--n-dir"]),
    (["probes", "--no-such-option"], ["--no-such-option"]),
])
def test_bad_option_is_one_line_before_any_computation(tmp_path, capsys, no_computation, argv, needles):
    out = tmp_path / "out"
    _refused(capsys, argv + ["--out", str(out)], *needles)
    assert not out.exists()


@pytest.mark.parametrize("cmd", ["biaxial", "probes", "domain"])
def test_unusable_out_refused_before_any_computation(tmp_path, capsys, no_computation, cmd):
    f = tmp_path / "a_file"
    f.write_text("keep me")
    _refused(capsys, [cmd, "--out", str(f)], "--out", "existing file")
    _refused(capsys, [cmd, "--out", str(f / "sub")], "--out")
    # /proc takes no new file, whoever runs the test (a chmod-ed folder does not stop root)
    _refused(capsys, [cmd, "--out", "/proc/granular_w2_test/out"], "--out", "not writable")
    assert f.read_text() == "keep me"


def test_hparams_refuses_strings_and_bools():
    for kw in (dict(kn="1e6"), dict(r_g=True), dict(n_dir="36")):
        with pytest.raises(ValueError, match=next(iter(kw))) as e:
            HParams(**kw)
        assert isinstance(e.value, ParamError)
    assert HParams(kn=np.float64(1e6), n_dir=np.int64(36)).n_dir == 36


def test_update_refuses_a_state_of_other_parameters():
    P = HParams(n_dir=16)
    s = isotropic_state(P)
    zero = np.zeros((2, 2))
    assert np.allclose(update(s, zero, P)[0], P.p0 * np.eye(2), atol=1e-6 * P.p0)
    # the case: same n_dir, r_g doubled (a zero increment gave 1.3e8 Pa instead of 2e5)
    for other in (P.replace(r_g=2e-3), P.replace(kn=2e6), P.replace(kt=1e5), P.replace(phi_g=30.0),
                  P.replace(fabric_a=0.2)):
        with pytest.raises(ValueError, match="other parameters"):
            update(s, zero, other)
        with pytest.raises(ValueError, match="other parameters"):
            run_path(s, other, drained_biaxial(1e-5), 2)
    # p0 and alpha0 only shape the initial state (which the state holds): accepted
    update(s, zero, P.replace(p0=1e5, alpha0=40.0))
    # the key travels with every state the library makes
    r = run_path(s, P, drained_biaxial(1e-5), 3)
    b = broadcast_state(r.state, (4,))
    for st in (r.state, b, take_points(b, [1, 2]), update(b, np.zeros((2, 2, 4)), P)[2]):
        assert st.params_key == P.state_key


def test_update_refuses_nan_in_the_state():
    P = HParams(n_dir=16)
    s = isotropic_state(P)
    for field in ("d1", "N1", "l2", "cos_alpha"):
        bad = s._replace(**{field: s.d1.copy() if field == "d1" else getattr(s, field).copy()})
        getattr(bad, field)[3] = np.nan
        with pytest.raises(ValueError, match=f"non-finite values .* in {field}"):
            update(bad, np.zeros((2, 2)), P)


def test_domain_bisection_finds_the_first_firing_state():
    """check_every = 1 sweeps every state of the path in order (the first firing state by
    definition); the default bisects inside each block of 25 steps: the same steps. (The two
    run the path in different chunks, whose restarts change the stresses by round-off: 1e-9.)"""
    P = HParams(n_dir=36)
    kw = dict(d_eps1=2e-4, n_dir_probe=72)
    a = domain_point(P, 200e3, check_every=25, **kw)
    b = domain_point(P, 200e3, check_every=1, **kw)
    for e in ("eps1_w2", "eps1_w2sigma", "eps1_peak"):
        assert round(getattr(a, e) / 2e-4) == round(getattr(b, e) / 2e-4), e
    assert round(a.eps1_w2 / 2e-4) % 25 != 0          # inside a block: the bisection did the work
    cols = lambda d: [getattr(d, k) for k in DOMAIN_COLUMNS]     # noqa: E731
    assert np.allclose(cols(a), cols(b), rtol=1e-9, atol=0) and a.outcome == b.outcome == "complete"


def test_domain_prints_progress(tmp_path, capsys):
    out = tmp_path / "d"
    assert cli.main(["domain", "--sigma2", "150e3", "--n-dir", "16", "--n-probes", "16", "--d-eps1", "2e-4",
                     "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "bifurcation domain at sigma2 = 150000 Pa" in err and "done (1/1" in err


def test_probes_print_progress(tmp_path, capsys):
    assert cli.main(["probes", "--n-dir", "16", "--n-probes", "16", "--d-eps1", "2e-4", "--stress-step", "90",
                     "--eta-a", "0.9", "--out", str(tmp_path / "p")]) == 0
    err = capsys.readouterr().err
    for stage in ("drained path to point A", "strain probes at A", "stress probes every 90 deg", "writing"):
        assert stage in err


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_outputs_get_the_ordinary_file_mode(tmp_path, umask):
    old = os.umask(umask)
    try:
        write_csv(tmp_path / "a.csv", {"x": np.arange(3.0)})
    finally:
        os.umask(old)
    assert (tmp_path / "a.csv").stat().st_mode & 0o777 == 0o666 & ~umask


def test_compilation_announced_once_when_not_cached():
    def fake(index):
        return SimpleNamespace(signatures=[], targetoptions={},
                               _cache=SimpleNamespace(_cache_file=SimpleNamespace(_load_index=lambda: index)))
    s = io.StringIO()
    assert not announce_compilation([fake({"sig": 1})], s) and s.getvalue() == ""
    assert announce_compilation([fake({"sig": 1}), fake({}), fake({})], s)
    assert s.getvalue().count("compiling kernels, once: one to two minutes") == 1


def test_fig4_marks_the_peak_and_fig9_legend_is_off_the_curves(monkeypatch, tmp_path, sweep_A):
    from hmodel import plots
    figs = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figs.append(fig))
    e = np.linspace(0, 0.04, 41)
    plots.fig_q_eps1([("H-model", e, 1e5 * np.sin(40 * e))], tmp_path / "f4.png", point_a=(0.02, 7e4),
                     peak=(e[np.argmax(np.sin(40 * e))], 1e5))
    ax = figs[-1].axes[0]
    assert any(t.get_text().startswith("peak") for t in ax.texts)
    plots.fig_w2_split(sweep_A, tmp_path / "f9.png")
    fig = figs[-1]
    fig.canvas.draw()
    leg = fig.axes[0].get_legend().get_window_extent()
    for a in fig.axes:
        assert not leg.overlaps(a.get_window_extent())


@pytest.mark.parametrize("sig,name,code,workers", [(signal.SIGTERM, "SIGTERM", 143, "1"),
                                                    (signal.SIGINT, "Ctrl-C", 130, "2")])
def test_interrupt_is_one_line_and_its_exit_code(tmp_path, sig, name, code, workers):
    """A domain run stopped after it started (in this process, or with worker processes):
    the exit code of the signal and one line saying where it stopped."""
    out = tmp_path / "d"
    rc, lines = interrupt_after(["hmodel", "domain", "--sigma2", "100e3,200e3", "--n-dir", "36",
                                 "--d-eps1", "1e-6", "--workers", workers, "--out", str(out)],
                                "bifurcation domain", sig)
    assert rc == code
    assert len(lines) == 1 and lines[0].startswith(f"interrupted ({name}) during bifurcation domain"), lines
    assert not out.exists()


def test_library_refuses_eta_and_sigma_norm_out_of_range(state_A):
    from hmodel.experiment import state_at_eta
    from hmodel.probes import stress_probes
    P = HParams(n_dir=16)
    for eta in (float("nan"), -1.0, 0.0, 2.0):
        with pytest.raises(ValueError, match="eta"):
            state_at_eta(P, eta, d_eps1=1e-4)
    for norm in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="sigma_norm"):
            stress_probes(state_A, HParams(), [0.0], sigma_norm=norm)


_SIGNAL_IN_NUMBA_CALLBACK = r"""
import os, signal, sys
import numpy as np, numba
import numba.core.serialize as S
from common.options import Parser, run_cli

@numba.njit
def two_arrays(a):
    return a.copy(), a.copy()

a = np.zeros(3)
two_arrays(a)

# Numba's unpickling callback, which compiled code calls from C to box each returned array, sends
# the signal to its own process on its 3rd call: the handler then runs with that callback on the
# stack, between the first and the second array of the tuple being boxed. (The C helper keeps the
# function object, so its code is swapped in place; the globals are those of numba's module.)
S._calls, S._signum, S._os = [0], int(sys.argv[1]), os
def callback(address, bytedata, hashed):
    _calls[0] += 1
    if _calls[0] == 3:
        _os.kill(_os.getpid(), _signum)
    key = (address, hashed)
    try:
        obj = _unpickled_memo[key]
    except KeyError:
        _unpickled_memo[key] = obj = cloudpickle.loads(bytedata)
    return obj
S._numba_unpickle.__code__ = callback.__code__

def run(args, stage):
    stage.at("the loop")
    while True:
        two_arrays(a)

sys.exit(run_cli(Parser(), [], run))
"""


@pytest.mark.parametrize("sig,name,code", [(signal.SIGTERM, "SIGTERM", 143),
                                           (signal.SIGINT, "Ctrl-C", 130)])
def test_a_signal_inside_numbas_callback_is_still_one_line(sig, name, code):
    # CI met this one: Numba's tuple boxing carries on past a failed element, so an exception
    # raised inside its callback came out as a SystemError with a traceback, exit 1
    import subprocess
    import sys
    p = subprocess.run([sys.executable, "-c", _SIGNAL_IN_NUMBA_CALLBACK, str(int(sig))],
                       capture_output=True, text=True, timeout=HANG_S,
                       preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert p.returncode == code, p.stderr
    assert p.stderr.strip() == f"interrupted ({name}) during the loop; no output written yet"
