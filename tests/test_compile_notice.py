"""One copy of the code, and the notice of a first compilation in a script as in the CLI.

After the README's set-up (an editable install), ``python -m ...`` from the repository's root and
a script anywhere else import the same files, so Numba's cache (beside the sources) serves both
(tests/test_api_examples.py checks that a script run elsewhere compiles nothing the root has
compiled). A library call that compiles a kernel of hmodel, fem or dem says so once on stderr
(``common.options.listen_for_compilation``), as the CLI does before its run.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numba
import pytest

import hmodel  # noqa: F401  (registers the listener)
from common import options
from tests._interrupt import HANG_S

ROOT = Path(__file__).resolve().parents[1]


def _njit_in(module_name, body="x + 1"):
    """A new Numba function whose module is ``module_name`` (compiled at its first call)."""
    ns = {"__name__": module_name}
    exec(f"def f(x):\n    return {body}\n", ns)
    return numba.njit(ns["f"])


@pytest.fixture
def not_yet_announced(monkeypatch):
    monkeypatch.setattr(options, "_compile_announced", False)


def test_first_compilation_of_a_kernel_is_announced_once(not_yet_announced, capsys):
    assert _njit_in("hmodel._notice_check")(1) == 2
    assert capsys.readouterr().err.splitlines() == [options.COMPILE_NOTICE]
    assert _njit_in("dem._notice_check", "x + 2")(1) == 3      # compiled too: said once only
    assert _njit_in("fem._notice_check", "x * 2")(2.0) == 4.0
    assert capsys.readouterr().err == ""


def test_other_packages_compile_silently(not_yet_announced, capsys):
    assert _njit_in("a_users_script")(1) == 2
    assert _njit_in("hmodelish.kernels")(1) == 2
    assert capsys.readouterr().err == ""
    assert not options._compile_announced


def test_cached_function_is_not_announced(not_yet_announced, capsys):
    f = _njit_in("hmodel._notice_check")
    f(1)
    capsys.readouterr()
    options._compile_announced = False
    f(5)              # compiled in this process: no compilation, no notice
    assert capsys.readouterr().err == ""


def test_the_cli_notice_silences_the_listener(not_yet_announced, capsys):
    class Uncached:
        signatures = []
        targetoptions = {}

        class _cache:
            class _cache_file:
                @staticmethod
                def _load_index():
                    return {}
    assert options.announce_compilation([Uncached])
    _njit_in("hmodel._notice_check")(1)
    assert capsys.readouterr().err.splitlines() == [options.COMPILE_NOTICE]


def test_the_listener_is_registered_once():
    from numba.core import event
    n = len(event._registered["numba:compile"])
    options.listen_for_compilation()
    import dem  # noqa: F401
    assert len(event._registered["numba:compile"]) == n


def test_one_copy_of_the_code(tmp_path):
    """From another folder, without PYTHONPATH, the packages are the repository's files (the
    README's editable install), not a second copy in site-packages."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run([sys.executable, "-c", "import hmodel, fem, dem; "
                        "print('\\n'.join(m.__file__ for m in (hmodel, fem, dem)))"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, r.stderr
    for f in r.stdout.split():
        assert Path(f).resolve().is_relative_to(ROOT), (
            f"{f}: a copy outside the repository; install with pip install -e . (README)")
