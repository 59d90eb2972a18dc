"""The cross-check as a graph (``crosscheck.run``): the DEM's stages that need only its biaxial
test (the relaxations and probe runs of its domain, the burst's path, staircase and probes) run
on one pool of workers, the burst's staircase first. What this may change is when a run runs,
never what it gives: every file of a small run (300 disks, two probe directions, the burst
from rest) on one pool of two workers is the same bits as the run with the stages one after the
other on one worker, but for the columns and fields that are wall times or this machine's
paths. About a minute (two runs)."""
import csv
import json
import math
import os

import pytest

from crosscheck import run_crosscheck
from crosscheck.report import graph_lines
from crosscheck.run import critical_path

# columns and fields that measure the run, not the mechanics
TIMING_COLUMNS = {"time_s", "seconds", "wall_time"}
RUN_FIELDS = {"wall_time", "rest_search_wall_time", "seconds", "time_s", "biaxial", "note",
              "update", "assemble",
              "solve", "total", "timings", "graph"}


def _run(out, graph, workers):
    return run_crosscheck(out, n=300, rate=0.1, workers=workers, fem_mesh=(2, 4), fem_n_dir=72,
                          dem_alphas=[0.0, 240.0], dem_domain=False, domain=False, graph=graph,
                          verbose=False)


def _same_json(a, b, where):
    if isinstance(a, dict):
        assert set(a) == set(b), where
        for k in a:
            if k not in RUN_FIELDS:
                _same_json(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same_json(x, y, f"{where}[{i}]")
    elif isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        assert math.isnan(b), where
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    seq = tmp_path_factory.mktemp("sequential")
    par = tmp_path_factory.mktemp("graph")
    # one after the other on one worker (every run in this process), one pool of two workers
    _run(seq, False, 1)
    _run(par, True, 2)
    return seq, par


def test_the_graph_gives_the_files_of_the_sequential_run(two_runs):
    seq, par = two_runs
    files = sorted(os.path.relpath(os.path.join(r, f), seq) for r, _, fs in os.walk(seq)
                   for f in fs)
    assert files == sorted(os.path.relpath(os.path.join(r, f), par) for r, _, fs in os.walk(par)
                           for f in fs)
    assert "burst/dem/stairs.csv" in files and "dem/domain/domain.csv" in files
    n_csv = 0
    for f in files:
        a, b = seq / f, par / f
        if f.endswith(".csv"):
            with open(a) as fa, open(b) as fb:
                ra, rb = list(csv.reader(fa)), list(csv.reader(fb))
            assert ra[0] == rb[0] and len(ra) == len(rb), f
            keep = [k for k, c in enumerate(ra[0]) if c not in TIMING_COLUMNS]
            assert [[r[k] for k in keep] for r in ra] == [[r[k] for k in keep] for r in rb], f
            n_csv += 1
        elif f.endswith(".json") and f not in ("command.json",):
            _same_json(json.loads(a.read_text()), json.loads(b.read_text()), f)
        elif f.endswith((".png", ".npz", ".jsonl")):
            if f.endswith(".jsonl"):
                # journals: the same records, in the order the runs finished
                la = sorted(_strip(line) for line in a.read_text().splitlines())
                lb = sorted(_strip(line) for line in b.read_text().splitlines())
                assert la == lb, f
            elif f.endswith(".npz"):
                # a zip's entries carry the time they were written: the arrays, to the bit
                import numpy as np
                with np.load(a, allow_pickle=False) as za, np.load(b, allow_pickle=False) as zb:
                    assert za.files == zb.files, f
                    for k in za.files:
                        if k == "meta":     # the run's record (JSON), wall times among it
                            _same_json(json.loads(str(za[k])), json.loads(str(zb[k])), f)
                        else:
                            assert za[k].tobytes() == zb[k].tobytes(), (f, k)
            else:
                assert a.read_bytes() == b.read_bytes(), f
    assert n_csv >= 10


def _strip(line):
    r = json.loads(line)
    for k in ("wall_time", "seconds", "time_s"):
        r.pop(k, None)
    return json.dumps(r, sort_keys=True)


def test_the_report_gives_the_stages_and_the_critical_path(two_runs):
    seq, par = two_runs
    g = json.loads((par / "conclusions.json").read_text())["graph"]
    s = json.loads((seq / "conclusions.json").read_text())["graph"]
    assert g["mode"] == "graph" and s["mode"] == "sequential"
    names = {st["name"] for st in g["stages"]}
    dom, bur = "DEM relaxations and probes (its domain)", \
        "DEM burst R=-2 f=0.9 (path, staircase, probes)"
    assert {dom, bur, "DEM compaction and biaxial test"} <= names
    by = {st["name"]: st for st in g["stages"]}
    # on one pool the two DEM stages start together, after the biaxial test
    assert by[dom]["start"] == pytest.approx(by[bur]["start"], abs=1.0)
    assert by[dom]["start"] >= by["DEM compaction and biaxial test"]["end"]
    # one after the other: the burst starts once the domain has ended
    sb = {st["name"]: st for st in s["stages"]}
    assert sb[bur]["start"] >= sb[dom]["end"]
    last = max(g["stages"], key=lambda st: st["end"])["name"]
    assert g["critical_path"][-1] == last and g["critical_path"][0] == \
        "H-model (path, probes, domain)"
    rep = (par / "report.md").read_text()
    assert "Critical path" in rep and " -> ".join(g["critical_path"]) in rep


def test_critical_path_follows_what_each_stage_waited_for():
    # a synthetic graph: b and c wait for a; d waits for b only, though c ends later;
    # e runs in this process after d
    stages = [{"name": "a", "start": 0, "end": 2, "after": []},
              {"name": "b", "start": 2, "end": 5, "after": ["a"]},
              {"name": "c", "start": 2, "end": 9, "after": ["a"]},
              {"name": "d", "start": 5, "end": 8, "after": ["b"]},
              {"name": "e", "start": 9.5, "end": 12, "after": ["c"]}]
    g = critical_path(stages, 12.5)
    assert g["critical_path"] == ["a", "c", "e"]
    assert g["busy"] == pytest.approx(2 + 3 + 7 + 3 + 2.5) and g["wall_time"] == 12.5
    # without e, the path ends with c (it ends last), not through d
    g = critical_path(stages[:4], 9)
    assert g["critical_path"] == ["a", "c"]
    # d's own chain: it waited for b, which waited for a
    g = critical_path([s for s in stages if s["name"] in "abd"], 8)
    assert g["critical_path"] == ["a", "b", "d"]
    g["mode"] = "graph"
    text = "\n".join(graph_lines(g))
    assert "a -> b -> d" in text and "| d | 5.0 | 8.0 | b |" in text


def test_the_cluster_estimate_replays_the_graph(two_runs, capsys):
    # bench/cluster_estimate.py --graph on the run: the two DEM stages one after the other and
    # as one pool, from the run's own step counts; one pool is never longer, and on one worker
    # the two are the same sum of steps
    import importlib.util
    from pathlib import Path
    _, par = two_runs
    script = Path(__file__).resolve().parents[2] / "bench" / "cluster_estimate.py"
    spec = importlib.util.spec_from_file_location("cluster_estimate", script)
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    m.main([str(par), "--graph", "--workers", "1,2,8"])
    rows = {int(line.split()[0]): [float(x) for x in line.split()[1:]]
            for line in capsys.readouterr().out.splitlines() if line.split()[0].isdigit()}
    assert set(rows) == {1, 2, 8}
    assert rows[1][4] == 1.0
    for n in (2, 8):
        assert rows[n][4] <= 1.0 and rows[n][3] <= rows[n][2] + 1e-9
    runs = m.burst_runs(str(par / "burst" / "dem"))
    waves = m.stage_steps(str(par / "dem" / "domain"))
    assert m.replay_pool(runs, waves, 1) == m.replay_pool(runs, None, 1) + sum(map(sum, waves))
