"""bench/kernel_ab.py refuses bad input before it imports the kernels or compacts a sample: one
line naming the option and its allowed range, exit 2. (The comparison itself compiles a second
copy of the kernels, one to two minutes: it is run by hand, docs/performance.md.)"""
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "kernel_ab.py"
KERNELS = Path(__file__).resolve().parents[2] / "dem" / "kernels"


@pytest.mark.parametrize("args, names", [
    (["--base", "/nonexistent/dem/kernels"], "--base: allowed a checkout's dem/kernels folder"),
    (["--base", str(KERNELS.parent)], "--base: allowed a checkout's dem/kernels folder"),
    (["--base", str(KERNELS), "--pairs", "0"], "--pairs: allowed integers >= 1"),
])
def test_bad_input_is_one_line_and_exit_2(args, names, tmp_path):
    res = subprocess.run([sys.executable, str(SCRIPT), *args, "--cache", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert names in res.stderr.strip().splitlines()[-1]
    assert "Traceback" not in res.stderr and not list(tmp_path.iterdir())
