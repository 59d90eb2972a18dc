"""python -m fem biaxial: the thin argparse layer over run_biaxial."""
import subprocess
import sys


from fem.__main__ import main
from fem.output import read_curve
from tests._interrupt import HANG_S


def test_cli_small_run(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["biaxial", "--nx", "2", "--ny", "4", "--n-dir", "16", "--eps1-max", "0.002",
               "--d-eps1", "5e-4", "--imperfection", "spot", "--imp-phi-g", "18", "--quiet",
               "--out", str(out)])
    assert rc == 0
    for f in ("curve.csv", "fields.xdmf", "fields.h5", "curve.png", "summary.json", "newton.log"):
        assert (out / f).stat().st_size > 0, f
    c = read_curve(out / "curve.csv")
    assert len(c["step"]) == 5 and abs(c["eps1"][-1] - 0.002) < 1e-12
    text = capsys.readouterr().out
    assert "material point" in text and "det K" in text


def test_cli_bad_option_exit_code(tmp_path, capsys):
    rc = main(["biaxial", "--nx", "0", "--out", str(tmp_path / "x"), "--quiet"])
    assert rc == 2
    assert "nx" in capsys.readouterr().err


def test_module_entry_point_help():
    r = subprocess.run([sys.executable, "-m", "fem", "biaxial", "--help"], capture_output=True,
                       text=True, timeout=HANG_S)
    assert r.returncode == 0 and "--eps1-max" in r.stdout and "--n-dir" in r.stdout
