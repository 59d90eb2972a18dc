"""Bad input to `python -m dem` (and to `python -m crosscheck`, its `crosscheck` command until
issue 33): one line naming the option and its allowed range, exit code 2, no traceback, nothing
written; Ctrl-C / SIGTERM: one line, exit 130 / 143."""
import signal

import pytest

from tests._cli import run_dem as _run
from tests._interrupt import interrupt_after


CASES = [
    (["biaxial", "--eta-a", "nan"], "--eta-a"),
    (["biaxial", "--eta-a", "-1"], "--eta-a"),
    (["biaxial", "--threads", "0"], "--threads"),
    (["biaxial", "--n", "0"], "--n"),
    (["biaxial", "--rate", "0"], "--rate"),
    (["biaxial", "--eps1-max", "1"], "--eps1-max"),
    (["biaxial", "--phi-g", "95"], "--phi-g"),
    (["biaxial", "--save-fractions", "0.9,1.5"], "--save-fractions"),
    (["probes", "--state", "S", "--workers", "0"], "--workers"),
    (["probes", "--state", "S", "--workers", "-2"], "--workers"),
    (["probes", "--state", "S", "--threads", "0"], "--threads"),
    (["probes", "--state", "S", "--stress-norm", "0"], "--stress-norm"),
    (["probes", "--state", "S", "--step-q3", "0"], "--step-q3"),
    (["probes", "--state", "S", "--max-steps", "0"], "--max-steps"),
    (["probes", "--state", "S", "--window", "10"], "--window"),
    (["probes", "--state", "S", "--directions", "10,10"], "--directions"),
    (["domain", "--biaxial", "B", "--strain-tol", "nan"], "--strain-tol"),
    (["crosscheck", "--workers", "0"], "--workers"),
    # a scheduler address is checked before anything runs (port 1 of this machine: refused)
    (["crosscheck", "--scheduler", "nonsense"], "--scheduler"),
    (["crosscheck", "--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),
    (["crosscheck", "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"], "--scheduler"),
    (["crosscheck", "--threads", "0"], "--threads"),
    (["crosscheck", "--start-fractions", "0.91"], "--start-fractions"),
    (["crosscheck", "--ratios", "1"], "--ratios"),
    (["domain", "--biaxial", "B", "--scheduler", "127.0.0.1:1"], "--scheduler"),
    (["probes", "--state", "S", "--scheduler", "tcp://127.0.0.1:x"], "--scheduler"),
]


@pytest.mark.parametrize("argv,option", CASES)
def test_bad_option_is_one_line_exit_2_nothing_written(argv, option, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run(argv + ["--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("error:") and option in err[0], err
    assert not out.exists()


def test_out_that_is_a_file_or_not_writable(tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    code, err = _run(["biaxial", "--n", "50", "--out", str(f)], capsys)
    assert code == 2 and len(err) == 1 and "--out" in err[0]


def test_missing_or_foreign_state_file(tmp_path, capsys):
    code, err = _run(["probes", "--state", str(tmp_path / "none.npz"), "--out",
                      str(tmp_path / "o")], capsys)
    assert code == 2 and len(err) == 1 and "no such file" in err[0]
    (tmp_path / "bad.npz").write_bytes(b"not a state")
    code, err = _run(["probes", "--state", str(tmp_path / "bad.npz"), "--out",
                      str(tmp_path / "o")], capsys)
    assert code == 2 and len(err) == 1 and "bad.npz" in err[0]
    assert not (tmp_path / "o").exists()


def test_probes_resume_refuses_a_folder_of_another_state(small_sample, tmp_path, capsys):
    from dem import io
    from dem.__main__ import main
    io.save_state(tmp_path / "s1.npz", small_sample)
    io.save_state(tmp_path / "s2.npz", small_sample._replace(x=small_sample.x + 1e-9))
    out = tmp_path / "p"
    main(["probes", "--state", str(tmp_path / "s1.npz"), "--out", str(out), "--directions",
          "0", "--workers", "1", "--max-steps", "20000"])
    capsys.readouterr()
    code, err = _run(["probes", "--state", str(tmp_path / "s2.npz"), "--out", str(out),
                      "--directions", "0", "--workers", "1", "--resume"], capsys)
    assert code == 2 and len(err) == 1 and "another state" in err[0], err


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_is_one_line(tmp_path, sig, code):
    # a run to 10 % strain (a minute), cut once it has written its first rows: the line names
    # the files written so far (issue 32: it said "no output written yet")
    out = tmp_path / "b"
    rc, err = interrupt_after(["dem", "biaxial", "--n", "300", "--eps1-max", "0.1", "--rate",
                               "0.05", "--out", str(out), "--no-vtk"],
                              "[biaxial] step", sig=sig, until=lambda: (out / "biaxial.csv").exists())
    assert rc == code
    err = [line for line in err if not line.startswith("[biaxial]")]     # its progress lines
    assert len(err) == 1 and err[0].startswith("interrupted") and "--resume" in err[0], err
    assert "no output written yet" not in err[0] and f"written so far in {out}: " in err[0], err
    assert "biaxial.csv" in err[0] and "params.json" in err[0], err


def test_scheduler_without_dask_distributed_is_one_line(monkeypatch, tmp_path, capsys):
    import sys
    monkeypatch.setitem(sys.modules, "distributed.comm.addressing", None)   # import fails
    code, err = _run(["crosscheck", "--scheduler", "tcp://127.0.0.1:8786", "--out",
                      str(tmp_path / "o")], capsys)
    assert code == 2 and len(err) == 1 and "--scheduler needs dask.distributed" in err[0], err
    assert not (tmp_path / "o").exists()
