"""The reference manual, docs/reference/: generated from the parsers and the code's column
constants, complete, and its examples run.

- The committed pages are what ``python docs/reference/make.py`` writes now: an option added,
  renamed or given another default, a column added to a file's constant, without the pages
  regenerated, fails here (the message says which page and how to regenerate).
- Nothing is left without a description or a unit: every option of every command, every column
  and every key of every file the pages list (the script's "gaps").
- Every command of the four command lines (point, hmodel, fem, dem) has its page (and the cross-check's two, ``python -m crosscheck`` and ``python -m crosscheck.fit``),
  the README's commands among them; the README and the parts' docs link the manual.
- Every page's example runs as written, in one working folder in the order of the pages'
  "needs" (a run of ``dem probes`` reads the states the example of ``dem biaxial`` wrote), from a
  folder where `docs/` is the repository's (the gallery's curve that ``hmodel fit`` reads): it
  must exit 0 and write every file the page lists (but those written only with an option the
  example does not give, or only sometimes), each CSV with the header the page lists, in that
  order, and each JSON file (or printed ``key: value`` lines) with the keys it lists, no more.
  The full commands beside the small ones are parsed, not run.
"""
from __future__ import annotations

import csv
import glob
import importlib.util
import json
import os
import itertools
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests._interrupt import HANG_S

ROOT = Path(__file__).resolve().parents[1]
REF = ROOT / "docs" / "reference"


def _load_make():
    spec = importlib.util.spec_from_file_location("reference_make", REF / "make.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod            # its dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


MAKE = _load_make()
CMDS = MAKE.commands()


@pytest.fixture(scope="module")
def built():
    return MAKE.build()


def test_no_gaps(built):
    _, gaps = built
    assert not gaps, ("the reference manual cannot say everything (describe these in "
                      "docs/reference/src/, then run python docs/reference/make.py):\n"
                      + "\n".join(gaps))


def test_committed_pages_are_the_generated_ones(built):
    pages, _ = built
    diff = MAKE.differences(pages)
    assert not diff, ("docs/reference/ is not what its sources and the parsers give: run "
                      "`python docs/reference/make.py` and commit the pages\n" + "\n\n".join(diff))


def test_every_command_has_a_page():
    """Every command of the four parsers (21: point's 6, hmodel's 6, fem's 2, dem's 7) and the
    cross-check's two have a page (the README's table names them all), and every page is a
    command."""
    readme = (ROOT / "README.md").read_text()
    listed = {" ".join(["python", "-m", *itertools.takewhile(lambda w: not w.startswith("-"),
                                                              m.split()[2:4])])
              for m in re.findall(r"^\| `(python -m [^`]+)`", readme, re.M)}
    have = {c for c, _, _ in CMDS.values()}
    assert listed <= have, f"README commands without a page: {sorted(listed - have)}"
    assert len({c for c in have if c.count(" ") == 3}) == 21, sorted(have)
    assert {"python -m crosscheck", "python -m crosscheck.fit"} <= have
    pages = {p.stem for p in REF.glob("*.md")} - {"README", "vocabulary"}
    assert pages == set(CMDS), (pages ^ set(CMDS))


def test_the_manual_is_linked():
    readme = (ROOT / "README.md").read_text()
    assert "](docs/reference/README.md)" in readme or "](docs/reference/)" in readme
    for part in ("hmodel.md", "fem.md", "dem.md", "burst.md"):
        text = (ROOT / "docs" / part).read_text()
        assert "reference/" in text, f"docs/{part} does not link the reference manual"


def test_links_of_the_pages_exist(built):
    pages, _ = built
    for name, text in pages.items():
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if "://" in target or target.startswith("#"):
                continue
            path = (REF / target.split("#")[0]).resolve()
            assert path.exists(), f"docs/reference/{name} links to {target}, which does not exist"
            if "#" in target and path.suffix == ".md":
                text_ = pages.get(path.name) if path.parent == REF else path.read_text()
                heads = {MAKE.anchor(h) for h in re.findall(r"^#+ (.+)$", text_, re.M)}
                assert target.split("#")[1] in heads, (
                    f"docs/reference/{name} links to {target}: no such heading there")


# -- the examples ---------------------------------------------------------------------------
def _source(slug):
    return MAKE.read_source(slug)


def _order():
    """The pages in the order their examples run: each after the ones it needs."""
    out, seen = [], set()

    def visit(slug):
        if slug in seen:
            return
        seen.add(slug)
        for n in _source(slug).needs:
            visit(n)
        out.append(slug)
    for slug in CMDS:
        visit(slug)
    return out


ORDER = _order()


def _argv(line):
    words = shlex.split(line)
    assert words[:2] == ["python", "-m"], f"an example is not a `python -m` command: {line}"
    return words[2], words[3:]


def _parser_of(module, argv):
    """The (sub)parser of a command line, and the argv it parses."""
    if module.startswith("crosscheck"):                     # one command, no subcommands
        return CMDS[module.replace(".", "-")][1], argv
    return CMDS[f"{module}-{argv[0]}"][1], argv[1:]


@pytest.mark.parametrize("slug", list(CMDS))
def test_the_example_commands_parse(slug, tmp_path, monkeypatch):
    """Every example line, the small runs and the full ones, parses with the command's own
    parser (options written in full, values in range); parsing writes nothing."""
    src = _source(slug)
    monkeypatch.chdir(tmp_path)
    for line in src.runs + src.full:
        module, argv = _argv(line)
        parser, rest = _parser_of(module, argv)
        parser.parse_args(rest)
    assert any(_runs_the_command(slug, *_argv(line)) for line in src.runs), (
        f"{slug}: no example line runs {CMDS[slug][0]}")
    assert list(tmp_path.iterdir()) == []


def _runs_the_command(slug, module, argv):
    words = CMDS[slug][0].split()[2:]           # ["hmodel", "biaxial"], ["crosscheck.fit"]
    return words == [module, *argv[:len(words) - 1]]


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """One folder for every example, as a user runs them from the repository's root."""
    d = tmp_path_factory.mktemp("reference")
    (d / "docs").symlink_to(ROOT / "docs")
    return d


def _option(argv, name):
    return argv[argv.index(name) + 1] if name in argv else None


def _skipped(when, argv):
    """True if a file written "when" is not expected of this run: "unless --x [or --y]" with one
    of them given, "with --x" without it; any other condition: maybe (checked if there)."""
    m = re.fullmatch(r"unless (--[\w-]+(?: or --[\w-]+)*)", when)
    if m:
        return any(o in argv for o in m.group(1).split(" or "))
    m = re.fullmatch(r"with (--[\w-]+)", when)
    if m:
        return m.group(1) not in argv
    return None


def _match(doc, header):
    """The header row against the documented columns (names, ``name?`` optional,
    ``{placeholder}`` one or more columns): True if they agree in order."""
    def go(i, j):
        if i == len(doc):
            return j == len(header)
        c = doc[i]
        if c.placeholder:
            return any(go(i + 1, k) for k in range(j + 1, len(header) + 1))
        if j < len(header) and header[j] == c.name and go(i + 1, j + 1):
            return True
        return c.optional and go(i + 1, j)
    return go(0, 0)


def _key_pattern(name):
    return re.compile("^" + re.sub(r"\\\{\w+\\\}", r"\\d+", re.escape(name)) + "$")


def _check_keys(what, doc, keys):
    pats = [(c, _key_pattern(c.name)) for c in doc]
    undocumented = [k for k in keys if not any(p.match(k) for _, p in pats)]
    missing = [c.name for c, p in pats if not c.optional and not any(p.match(k) for k in keys)]
    assert not undocumented and not missing, (
        f"{what}: keys written but not on the page: {undocumented}; on the page but not "
        f"written: {missing}")


def _check_file(slug, f, path, stdout):
    what = f"{slug}: {f.name}"
    if f.same:
        _, other, _ = MAKE.same_as(f, CMDS)
        f = other
    kind, cols, _ = MAKE.file_columns(f, what)
    if f.name == "stdout":
        keys = re.findall(r"^([^\s:]+): ", stdout, re.M)
        _check_keys(what, cols, keys)
        return
    if kind == "columns":
        with open(path, newline="") as fh:
            header = next(csv.reader(fh))
        assert _match(cols, header), (f"{what}: the header row {header} is not the page's "
                                      f"columns {[c.name for c in cols]}")
    elif kind == "keys":
        with open(path) as fh:
            doc = json.load(fh)
        assert isinstance(doc, dict), what
        _check_keys(what, cols, list(doc))


@pytest.mark.parametrize("slug", ORDER)
def test_the_example_runs_and_writes_what_the_page_says(slug, workdir):
    src = _source(slug)
    env = dict(os.environ, MPLBACKEND="Agg",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    own = None
    stdout = ""
    for line in src.runs:
        module, argv = _argv(line)
        # a timeout only against a hang (no timing assertion)
        r = subprocess.run([sys.executable, "-m", module, *argv], cwd=workdir, env=env,
                           capture_output=True, text=True, timeout=HANG_S)
        assert r.returncode == 0, f"{line}: exit {r.returncode}\n{r.stderr[-3000:]}"
        if _runs_the_command(slug, module, argv):
            own, stdout = argv, r.stdout
    assert own is not None, f"{slug}: no example line runs {CMDS[slug][0]}"
    where = _option(own, src.files_in)
    assert where, f"{slug}: the example gives no {src.files_in}"
    for f in src.files:
        if f.name == "stdout":
            _check_file(slug, f, None, stdout)
            continue
        path = workdir / where if f.name == "FILE" else workdir / where / f.name
        skip = _skipped(f.when, own) if f.when else False
        if skip:
            continue
        found = sorted(glob.glob(str(path))) if any(ch in f.name for ch in "*?[") else (
            [str(path)] if path.exists() else [])
        if skip is None and not found:
            continue                    # written only sometimes, and not this time
        assert found, f"{slug}: `{line}` did not write {f.name}, which the page lists"
        for p in found:
            if os.path.isfile(p):
                _check_file(slug, f, p, stdout)


def test_the_checks_of_a_header_and_of_keys():
    """The example's checks fail where they must (fast: no command runs)."""
    C = MAKE.Column
    doc = [C("eps1"), C("q"), C("eps_v", optional=True), C("{varied}", placeholder=True), C("x")]
    assert _match(doc, ["eps1", "q", "eps_v", "a", "x"])
    assert _match(doc, ["eps1", "q", "a", "b", "x"])
    assert not _match(doc, ["eps1", "q", "x"])                 # the placeholder is one or more
    assert not _match(doc, ["q", "eps1", "a", "x"])            # the order is the page's
    assert not _match(doc, ["eps1", "q", "a", "x", "new"])     # a column the page does not list
    assert not _match([C("a"), C("b")], ["a"])
    keys = [C("n"), C("particle_steps_per_s_{N}_threads"), C("written_over", optional=True)]
    _check_keys("ok", keys, ["n", "particle_steps_per_s_2_threads"])
    with pytest.raises(AssertionError, match="not on the page: \\['new'\\]"):
        _check_keys("x", keys, ["n", "particle_steps_per_s_2_threads", "new"])
    with pytest.raises(AssertionError, match="not written: \\['n'\\]"):
        _check_keys("x", keys, ["particle_steps_per_s_4_threads"])
    assert _skipped("unless --no-vtk", ["--no-vtk"]) and not _skipped("unless --no-vtk", [])
    assert _skipped("unless --no-burst or --no-dem", ["--no-dem"])
    assert _skipped("with --save-etas", []) and not _skipped("with --save-etas", ["--save-etas"])
    assert _skipped("when fitted", []) is None


def test_a_stale_page_and_a_gap_are_found(built, monkeypatch):
    """An option added to a parser without the pages regenerated makes a page differ; a column
    without a description is a gap."""
    pages, _ = built
    import hmodel.cli as hcli
    real = hcli.build_parser

    def more():
        ap = real()
        sub = [a for a in ap._actions if a.__class__.__name__ == "_SubParsersAction"][0]
        MAKE_add = __import__("common.options", fromlist=["add"]).add
        MAKE_add(sub.choices["biaxial"], "--smooth", 0.001)
        return ap
    monkeypatch.setattr(hcli, "build_parser", more)
    new, gaps = MAKE.build()
    assert not gaps
    assert "`--smooth SMOOTH`" in new["hmodel-biaxial.md"]
    assert new["hmodel-biaxial.md"] != pages["hmodel-biaxial.md"]
    assert any("hmodel-biaxial.md" in d for d in MAKE.differences(new))
    f = MAKE.FileDoc("x.csv", columns=["eps1", "a_new_column"])
    with pytest.raises(MAKE.Gap, match="a_new_column has no description"):
        for c in MAKE.resolve(f.columns, "x"):
            MAKE.describe(c, f, "dem", MAKE.glossary(), {}, "x")
