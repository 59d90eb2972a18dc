"""The README's commands, as written.

Every command of the README (its code blocks and the first column of its table of commands) is
checked against the parser its CLI builds (`hmodel.cli.build_parser`, `point.cli.build_parser`,
`fem.__main__.build_parser`,
`dem.__main__.build_parser`, `crosscheck.__main__.build_parser`): the subcommand exists (the
cross-check is one command, without subcommands), every option is one of the (sub)command's own
option strings as written (no abbreviation), and the whole line parses. Parsing computes and
writes nothing; it runs in a temporary folder all the same.

The cheap rows run as written: those whose README time is at most CHEAP_S = 15 s (wall time on
the idle 2-core machine, warm cache: the issue's "cheap ones"). Today: `hmodel params`, `biaxial`,
`probes`, `domain`, `burst`, `fit` (on the gallery's DEM curve), `point params`, `biaxial`,
`probes`, `domain` (Drucker-Prager), `fem biaxial` (the set-up's main job) and with `--params`,
`dem params` and the 300-disk `dem biaxial`; the rest take from 18 s to an hour
(docs/performance.md). Each runs in a temporary working directory and must exit 0
and leave every file the row's "writes" column names in backticks (in its `--out` folder; for
`params`, `--out` is the file).
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from tests._interrupt import HANG_S

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_LINES = 150           # the "under ~150 lines"
CHEAP_S = 15.0            # README wall time, idle machine, warm cache [s]

SET_UP = ("python3 -m venv ", ". .venv/bin/activate", "pip install ", "python -m pytest")
CLIS = ("hmodel", "point", "fem", "dem", "crosscheck")


def _text():
    return README.read_text()


def _code_block_commands(text):
    """Every command line of the README's bash code blocks (comments dropped)."""
    out = []
    for block in re.findall(r"```(?:bash|sh)\n(.*?)```", text, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #")[0].strip()
            if line and not line.startswith("#"):
                out.append(line)
    return out


def _table_rows(text):
    """(command, writes, time) of every row of the table of commands."""
    rows = []
    for line in text.splitlines():
        if not line.startswith("| `python"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split(" | ")]
        assert len(cells) == 4, f"a row of the table of commands has {len(cells)} cells: {line}"
        cmd = re.fullmatch(r"`([^`]+)`", cells[0])
        assert cmd, f"the command cell is not one command in backticks: {cells[0]}"
        rows.append((cmd.group(1), re.findall(r"`([^`]+)`", cells[2]), cells[3]))
    return rows


def _seconds(time_cell):
    """The README's time of a row in seconds ("4 s", "[2 min](...)", "18-38 min": the larger),
    None for "?" (a command being added)."""
    m = re.search(r"(\d+(?:\.\d+)?)(?:-(\d+(?:\.\d+)?))?\s*(s|min)\b", time_cell)
    if not m:
        assert time_cell.strip() == "?", f"a time the test cannot read: {time_cell}"
        return None
    value = float(m.group(2) or m.group(1))
    return value * (60.0 if m.group(3) == "min" else 1.0)


def _segments(command):
    return [s.strip() for s in command.split("&&")]


def _cli(segment):
    """(module, argv) of a `python -m hmodel|point|fem|dem|crosscheck ...` command, else None."""
    words = shlex.split(segment)
    if words[:2] == ["python", "-m"] and len(words) > 2 and words[2] in CLIS:
        return words[2], words[3:]
    return None


def _all_cli_commands():
    text = _text()
    seen = []
    for command in _code_block_commands(text) + [r[0] for r in _table_rows(text)]:
        for seg in _segments(command):
            if _cli(seg) is None:
                assert seg.startswith(SET_UP), (
                    f"README command {seg!r}: neither a `python -m hmodel|point|fem|dem|crosscheck` command nor a "
                    "set-up step; teach tests/test_readme.py to check it")
            elif seg not in seen:
                seen.append(seg)
    return seen


def _parser(module):
    if module == "hmodel":
        from hmodel.cli import build_parser
    elif module == "point":
        from point.cli import build_parser
    elif module == "fem":
        from fem.__main__ import build_parser
    elif module == "crosscheck":
        from crosscheck.__main__ import build_parser
    else:
        from dem.__main__ import build_parser
    return build_parser()


def _subparser(parser, name):
    """The subcommand ``name`` of ``parser`` (None if it has no such one), or ``parser`` itself
    if it has no subcommands (``python -m crosscheck``)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices.get(name)
    return parser


def _check_available(module, argv):
    """Skip (naming it) a command or option being added on another branch and absent here;
    fail on any other unknown subcommand or option. Returns the subparser."""
    parser = _parser(module)
    sub = _subparser(parser, argv[0] if argv else None)
    if sub is None:
        raise AssertionError(f"`python -m {module}` has no subcommand {argv[0]!r}")
    options = argv if sub is parser else argv[1:]
    for word in options:
        if word.startswith("--"):
            option = word.split("=", 1)[0]
            if option not in sub._option_string_actions:
                raise AssertionError(f"`{sub.prog}` has no option {option} "
                                     "(written in full, as the README must)")
    return parser


@pytest.mark.parametrize("segment", _all_cli_commands())
def test_readme_command_parses(segment, tmp_path, monkeypatch):
    module, argv = _cli(segment)
    parser = _check_available(module, argv)
    monkeypatch.chdir(tmp_path)
    args = parser.parse_args(argv)        # an OptionError (one line, naming the option) fails
    assert args is not None
    assert list(tmp_path.iterdir()) == []     # parsing wrote nothing


def _cheap_rows():
    return [(cmd, files) for cmd, files, t in _table_rows(_text())
            if (s := _seconds(t)) is not None and s <= CHEAP_S]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """One folder for the cheap rows, run in the README's order as a newcomer runs them from the
    repository's root: a row may read what an earlier one wrote (`--params p.json`), and `docs/`
    is there (the gallery's curve that `hmodel fit` reads)."""
    d = tmp_path_factory.mktemp("readme")
    (d / "docs").symlink_to(ROOT / "docs")
    return d


@pytest.mark.parametrize("command,files", _cheap_rows())
def test_cheap_readme_command_runs(command, files, workdir):
    tmp_path = workdir
    module, argv = _cli(command)
    _check_available(module, argv)
    out = argv[argv.index("--out") + 1]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               MPLBACKEND="Agg")
    # a timeout only against a hang (no timing assertion)
    r = subprocess.run([sys.executable, "-m", module, *argv], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=HANG_S)
    assert r.returncode == 0, f"{command}: exit {r.returncode}\n{r.stderr[-3000:]}"
    if argv[0] == "params":
        assert files == [out] and (tmp_path / out).is_file()
    else:
        missing = [f for f in files if not (tmp_path / out / f).exists()]
        assert files and not missing, f"{command}: the README says it writes {missing}"


def test_cheap_rows_are_the_expected_ones():
    """The selection by time is what the module docstring says (a changed time in the README
    changes which commands run: say so there)."""
    assert [c.split(" --")[0] for c, _ in _cheap_rows()] == [
        "python -m hmodel params", "python -m hmodel biaxial", "python -m hmodel probes",
        "python -m hmodel domain", "python -m hmodel burst", "python -m hmodel fit",
        "python -m point params", "python -m point biaxial", "python -m point probes",
        "python -m point domain", "python -m fem biaxial", "python -m fem biaxial",
        "python -m fem biaxial", "python -m dem params",
        "python -m dem biaxial"]


def test_readme_is_short():
    n = len(_text().splitlines())
    assert n < MAX_LINES, f"README.md has {n} lines: the issue asks for under {MAX_LINES}"


def _section_commands(text, title):
    """The commands of the bash blocks of the README's section ``## title``."""
    m = re.search(rf"^## {re.escape(title)}\b.*?$(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert m, f"the README has no section '## {title}'"
    return _code_block_commands(m.group(1))


def test_setup_block_is_apart_from_the_tests_and_ci_runs_the_tests():
    """The set-up block makes a venv, installs and runs the main job, and nothing more (the
    issue: "the README's set-up separate from the tests"); the tests have a block of their own,
    which installs the test extras and runs the suite; .ci/run runs that test line exactly; the
    main job is a row of the table (so its outputs and time are stated, and it runs above)."""
    text = _text()
    setup = _section_commands(text, "Set-up")
    assert setup == ["python3 -m venv .venv && . .venv/bin/activate",
                     "pip install -e . && python -m fem biaxial --out out/fem"], setup
    # editable: `python -m ...` from the root and a script elsewhere import the same files
    assert not any("pytest" in line or "[test" in line for line in setup)
    tests = _section_commands(text, "Tests")
    assert tests == ['pip install -e ".[test,distributed]" && python -m pytest'], tests
    ci = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    assert tests[0] in ci, ".ci/run does not run the README's test command"
    main_job = _segments(setup[1])[1]
    assert main_job in [r[0] for r in _table_rows(text)]
    # the set-up comes first, the tests after it: a newcomer runs the main job before the suite
    assert text.index("## Set-up") < text.index("## Tests") < text.index("## Commands")


def test_readme_links_exist():
    for target in re.findall(r"\]\(([^)]+)\)", _text()):
        if "://" in target:
            continue
        path = target.split("#")[0]
        assert (ROOT / path).exists(), f"README links to {target}, which does not exist"
