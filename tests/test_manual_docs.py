"""The manual and the notebook apart (issue 32): docs/dem.md and docs/fem.md say what the code does
(the method, the rules, the definitions, the outputs) and hold no dated measurement; the
measurements live in the gallery's README files (each with the command that reproduces it and
the commit or date) and in docs/performance.md, and each of those is linked, so that nothing
moved out of the manuals is lost."""
from __future__ import annotations

import re
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
MANUALS = ("dem.md", "fem.md")

# what marks a dated measurement or the narrative of a sitting
DATED = {
    "a month's name": r"\b(January|February|March|April|May|June|July|August|September|October|"
                      r"November|December)\b",
    "a time in UTC": r"\bUTC\b",
    "an ISO date": r"\b\d{4}-\d{2}-\d{2}\b",
    "a clock time": r"\b\d{1,2}:\d{2}(-\d{1,2}:\d{2})?\b",
    "the code before an issue": r"\b[Bb]efore (this issue|issue #?\d+)",
    "a comparison against HEAD": r"\bHEAD\b",
    "a session or sitting": r"\b(this|previous|earlier|that|same|later|one|a) (session|sitting|release)s?\b",
    "a load average": r"\bload (average )?~?\d",
    "a run folder of a machine": r"/work/runs",
}


def _lines(name):
    return (DOCS / name).read_text().splitlines()


@pytest.mark.parametrize("name", MANUALS)
def test_the_manual_holds_no_dated_measurement(name):
    found = [f"{name}:{i}: {what}: {line.strip()[:100]}"
             for i, line in enumerate(_lines(name), 1)
             for what, pattern in DATED.items() if re.search(pattern, line)]
    assert not found, ("dated measurements in the manual (move them to docs/gallery/<folder>/"
                       "README.md or docs/performance.md with a one-line pointer):\n"
                       + "\n".join(found))


def _links(path):
    """(target path, anchor) of every relative link of a markdown file."""
    out = []
    for target in re.findall(r"\]\(([^)\s]+)\)", path.read_text()):
        if "://" in target or target.startswith("mailto:"):
            continue
        file, _, anchor = target.partition("#")
        out.append(((path.parent / file).resolve() if file else path.resolve(), anchor))
    return out


def _anchors(path):
    """GitHub's anchors of a markdown file's headings."""
    out = set()
    for title in re.findall(r"^#+ (.*)$", path.read_text(), re.M):
        out.add(re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-"))
    return out


def _notebook():
    return sorted(DOCS.glob("gallery/**/README.md")) + [DOCS / "performance.md"]


@pytest.mark.parametrize("path", [DOCS / m for m in MANUALS] + _notebook(),
                         ids=lambda p: str(p.relative_to(DOCS)))
def test_links_of_the_manuals_and_the_notebook_resolve(path):
    bad = [f"{t.relative_to(ROOT) if t.is_relative_to(ROOT) else t}#{a}"
           for t, a in _links(path)
           if (not t.exists() or (a and t.suffix == ".md" and a not in _anchors(t)))]
    assert not bad, f"{path.relative_to(ROOT)} links to what is not there: {bad}"


def test_every_gallery_readme_is_linked():
    """A measurement moved out of the manuals lands in a README that a reader can reach: every
    gallery README (or its folder) is the target of a link of another page."""
    pages = sorted(DOCS.rglob("*.md")) + [ROOT / "README.md"]
    targets = {t for p in pages for t, _ in _links(p)}
    orphans = [str(r.relative_to(DOCS)) for r in DOCS.glob("gallery/**/README.md")
               if r.resolve() not in targets and r.parent.resolve() not in targets]
    assert not orphans, f"gallery README files no page links to: {orphans}"


@pytest.mark.parametrize("readme", sorted(DOCS.glob("gallery/**/README.md")),
                         ids=lambda p: str(p.relative_to(DOCS)))
def test_a_gallery_readme_gives_its_command_and_its_date(readme):
    text = readme.read_text()
    assert re.search(r"`python (-m (hmodel|fem|dem)|bench/|docs/)", text), \
        f"{readme.relative_to(ROOT)}: no command that reproduces it"
    assert re.search(r"\b\d{1,2} (November|December) 20\d\d\b|\bcommit [0-9a-f]{7}", text), \
        f"{readme.relative_to(ROOT)}: no date or commit"


# what points outside the project: the specification's folder beside the repository, a machine's
# own folders (an output folder DIR/work/KEY of the calibration is the project's: "/work/" after a
# name is not a machine path)
OUTSIDE = re.compile(r"shared/(spec|reference|papers)|\.\./shared\b|(?<![\w/])/work/|(?<![\w/])/root/"
                     r"|(?<![\w/])/tmp/[\w.-]+/")


def _tracked_text_files():
    import subprocess
    names = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split()
    for n in names:
        p = ROOT / n
        if n == "tests/test_manual_docs.py" or not p.is_file() or p.stat().st_size > 4_000_000:
            continue
        try:
            yield n, p.read_text()
        except UnicodeDecodeError:
            continue


def test_no_file_points_outside_the_project():
    """A user has the project only: no file of it (code, docs, the galleries' records, tests)
    names the specification's folder beside the repository or a path of a development machine."""
    bad = [f"{n}:{i}: {line.strip()[:100]}" for n, text in _tracked_text_files()
           for i, line in enumerate(text.splitlines(), 1) if OUTSIDE.search(line)]
    assert not bad, "files point outside the project:\n" + "\n".join(bad[:40])
