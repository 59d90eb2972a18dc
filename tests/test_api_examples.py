"""The examples of docs/api.md run, as a user runs them, and the page shows them as they are.

Each file of docs/examples/ runs in a subprocess from an empty folder outside the repository
(no PYTHONPATH: the package as the README's editable install provides it) and must exit 0; it
writes only there. docs/api.md must show every example whole, in a ```python block after its
link, so that the page cannot drift from the code that runs. And a script run from another
folder compiles nothing that a run from the repository's root compiled already: one copy of
the code, one cache of kernels (the compile notice, common.options.COMPILE_NOTICE, is printed
at any compilation).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from common.options import COMPILE_NOTICE
from tests._interrupt import HANG_S

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "docs" / "examples").glob("*.py"))
API = ROOT / "docs" / "api.md"


def _env():
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["MPLBACKEND"] = "Agg"
    return env


def _run(argv, cwd):
    # a timeout only against a hang (the examples take seconds; a first compilation minutes)
    return subprocess.run([sys.executable, *argv], cwd=cwd, env=_env(), capture_output=True,
                          text=True, timeout=HANG_S)


def test_examples_exist():
    assert {p.name for p in EXAMPLES} >= {"hmodel_point.py", "hmodel_directions.py",
                                         "hmodel_burst.py", "hmodel_fit.py", "fem_specimen.py",
                                         "dem_sample.py"}


@pytest.mark.parametrize("example", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs_from_another_folder(example, tmp_path):
    r = _run([str(example)], tmp_path)
    assert r.returncode == 0, f"{example.name}: exit {r.returncode}\n{r.stderr[-3000:]}"
    assert r.stdout.strip(), f"{example.name} printed nothing"
    assert "Traceback" not in r.stderr and "Warning" not in r.stderr, r.stderr[-3000:]


@pytest.mark.parametrize("example", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_api_page_shows_the_example_whole(example):
    text = API.read_text()
    m = re.search(rf"\[`docs/examples/{re.escape(example.name)}`\]\(examples/"
                  rf"{re.escape(example.name)}\):\n\n```python\n(.*?)```\n", text, re.S)
    assert m, f"docs/api.md does not show docs/examples/{example.name}"
    assert m.group(1) == example.read_text(), (f"docs/api.md shows another text than "
                                               f"docs/examples/{example.name}")


def test_readme_links_the_api_page():
    assert "](docs/api.md)" in (ROOT / "README.md").read_text()


def test_no_second_compilation_from_another_folder(tmp_path):
    """The material point's example, first as ``python -m`` resolves it from the repository's
    root (the source tree first on sys.path), then from another folder: the second run loads
    every kernel the first compiled, so it prints no compile notice."""
    example = str(ROOT / "docs" / "examples" / "hmodel_point.py")
    first = _run(["-c", "import runpy, sys; runpy.run_path(sys.argv[1], run_name='__main__')",
                  example], ROOT)
    assert first.returncode == 0, first.stderr[-3000:]
    second = _run([example], tmp_path)
    assert second.returncode == 0, second.stderr[-3000:]
    assert COMPILE_NOTICE not in second.stderr, "a second compilation from another folder"
    assert second.stdout == first.stdout
