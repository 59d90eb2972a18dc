"""`python -m dem burst`: its outputs (docs/burst.md columns) on a 300-disk biaxial test, and bad
input refused in one line with exit code 2 before anything is computed or written."""
import json
import math
import shutil
import signal

import numpy as np
import pytest

from dem import io
from dem.anatomy import ANATOMY_COLUMNS
from dem.burst import (BURST_COLUMNS, HISTORY_COLUMNS, PATH_COLUMNS, PROBE_COLUMNS, REST_COLUMNS,
                       STAIR_COLUMNS)
from hmodel.burst_rule import RELEASE
from dem.settle import OUTCOMES

CONTRACT = {"burst.csv": ["ratio", "start_fraction", "eta_start", "eta_peak_c", "fraction_peak_c",
                          "eps1_peak_c", "c_start", "c_peak", "c_switch", "switch", "dc",
                          "outcome", "ke_growth", "ke_max", "w2_ext_end", "w2_int_end", "t_end",
                          "steps"],
            "history.csv": ["ratio", "start_fraction", "switch", "step", "t", "eps1", "eps2",
                            "c", "ke", "w2_ext", "w2_int"],
            "paths.csv": ["ratio", "start_fraction", "eps1", "eps2", "s1", "s2", "p", "q", "eta",
                          "c"]}


@pytest.fixture(scope="module")
def biaxial_300(tmp_path_factory):
    """A 300-disk drained biaxial test (0.05/s) with its state at 0.9 of the peak eta."""
    from dem import experiment
    from dem.params import DemParams
    out = tmp_path_factory.mktemp("bx300")
    experiment.run_biaxial(DemParams(n=300, seed=1), out, rate=0.05, eps_max=0.01,
                           verbose=False, figures=False, vtk=False, save_fractions=(0.9,))
    return out


def _run(argv, capsys):
    from dem.__main__ import main
    with pytest.raises(SystemExit) as e:
        main(argv)
    return e.value.code, capsys.readouterr().err.strip().splitlines()


def _burst_args(biaxial, out, workers):
    return ["burst", "--biaxial", str(biaxial), "--out", str(out), "--workers", str(workers),
            "--threads", "1", "--max-steps", "200000"]


@pytest.fixture(scope="module")
def burst_300(biaxial_300, tmp_path_factory):
    """`dem burst` on one worker, one thread, on the 300-disk test: (folder, {figure file:
    figure} as saved, what it printed on stdout)."""
    import contextlib
    from io import StringIO
    from dem.__main__ import main
    from tests import _figures as F
    out = tmp_path_factory.mktemp("burst300") / "burst"
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(StringIO()) as printed:
        caught = F.catch(mp)
        main(_burst_args(biaxial_300, out, 1))
    return out, caught, printed.getvalue()


def test_burst_writes_the_contract_outputs(burst_300, biaxial_300):
    from tests import _figures as F
    out, caught, printed = burst_300
    for name, cols in CONTRACT.items():
        header, rows = io.read_csv(out / name)
        assert set(cols) <= set(header), (name, set(cols) - set(header))
        assert rows, name
    assert io.read_csv(out / "burst.csv")[0] == BURST_COLUMNS
    assert io.read_csv(out / "history.csv")[0] == HISTORY_COLUMNS
    assert io.read_csv(out / "paths.csv")[0] == PATH_COLUMNS
    _, runs = io.read_csv(out / "burst.csv")
    _, hist = io.read_csv(out / "history.csv")
    _, path = io.read_csv(out / "paths.csv")
    peaked = runs[0]["eta_peak_c"] == runs[0]["eta_peak_c"]          # not nan
    assert peaked                     # the 300-disk path peaks: the staircase runs
    assert [r["switch"] for r in runs] == ["below", "past"]
    for r in runs:
        assert r["ratio"] == -2.0 and r["start_fraction"] == 0.9 and r["dc"] == 100.0
        assert r["outcome"] in OUTCOMES
        h = [x for x in hist if x["switch"] == r["switch"]]
        assert h[0]["step"] == 0 and h[-1]["step"] == r["steps"]
        # the contract's ke_growth, the three parts' one formula (point.burst_rule.ke_growth):
        # the largest E_c over E_c at the first record after the switch (the backbone's here)
        assert r["ke_growth"] == max(x["ke_backbone"] for x in h[1:]) / h[1]["ke_backbone"]
        assert r["c_switch"] == h[0]["c"] and r["c_target"] == r["c_switch"] + 100.0
    # the path: d eps2 = R d eps1 (to the round-off of ~50,000 steps of wall positions, 1e-10:
    # the tie itself is tested to round-off in test_burst) and c = s1 + R s2 on every record
    e1, e2 = np.array([x["eps1"] for x in path]), np.array([x["eps2"] for x in path])
    assert np.allclose(e2 - e2[0], -2.0 * (e1 - e1[0]), rtol=0, atol=1e-10)
    assert all(abs(x["c"] - (x["s1"] - 2.0 * x["s2"])) <= 1e-9 * abs(x["s1"]) for x in path)
    s = json.loads((out / "summary.json").read_text())
    assert s["options"]["dc"] == 100.0 and s["params"]["n"] == 300 and s["ratios"] == [-2.0]
    # the run's parameters in the shared file format: the states' own, and --params takes them
    from dem.params import DemParams, load_params
    assert load_params(out / "params.json") == DemParams.from_dict(s["params"])
    assert load_params(out / "params.json") == load_params(biaxial_300 / "params.json")
    for fig in ("fig_burst_c.png", "fig_burst_ke.png", "fig_burst_strain.png",
                "fig_burst_ledger.png", "fig_burst_anatomy.png", "fig_burst_k.png"):
        assert (out / fig).stat().st_size > 10_000
    # the anatomy at every check of the holds, and VTU files at the end of both runs (and at the
    # onset of the past run's burst): the past run ends with unstable contacts in clusters
    assert set(ANATOMY_COLUMNS) <= set(io.read_csv(out / "history.csv")[0])
    import meshio
    for kind in ("disks", "contacts"):
        for sw in ("below", "past"):
            assert meshio.read(out / "anatomy" / f"{kind}_R-2_f0.9_{sw}_end.vtu").points.size
        assert (out / "anatomy" / f"{kind}_R-2_f0.9_past_onset.vtu").exists()
    assert "burst: " in printed and "theory passes" in printed
    # from rest: the path's start and loaded peak relaxed at fixed strain (rest.csv: c at rest
    # below the loaded c), the staircase of holds (stairs.csv), each switch held by a dead load
    # from an equilibrium (its backbone kinetic energy at the switch within the rule's bound),
    # Eq. 1 closed in every hold
    _, rest = io.read_csv(out / "rest.csv")
    assert [x["state"] for x in rest] == ["start", "peak"]
    assert all(x["outcome"] == "equilibrium" and x["c_rest"] < x["c_loaded"] for x in rest)
    h_st, st = io.read_csv(out / "stairs.csv")
    assert h_st == STAIR_COLUMNS and io.read_csv(out / "rest.csv")[0] == REST_COLUMNS
    assert st[0]["c_from"] == rest[0]["c_rest"] and st[0]["role"] == "stair"
    for r in runs:
        assert r["hold"] == "dead_load" and r["wall_mass"] > 0 and r["holds"] == len(st)
        assert r["ke_switch"] <= s["options"]["ke_tol"] * 300
        assert r["eq1_bookkeeping"] <= 1e-8           # bookkeeping: an identity of the leapfrog
        assert r["c_loaded"] > r["c_rest"]            # the loaded path's c at that strain
        assert any(x["c_target"] == r["c_target"] and x["outcome"] == r["outcome"] for x in st)
    # the path's own W2 at rest, measured without a burst: a kinematic probe at every
    # equilibrium, each decided; k_path of the state every hold started from
    _, pr = io.read_csv(out / "probes.csv")
    assert io.read_csv(out / "probes.csv")[0] == PROBE_COLUMNS
    assert all(x["outcome"] == "equilibrium" and np.isfinite(x["k_path"]) for x in pr)
    for x in st:
        assert np.isfinite(x["k_path_from"])
        assert np.isfinite(x["k_path"]) == (x["outcome"] == "equilibrium"), x
    assert all(np.isfinite(x["k_path"]) for x in rest)
    # the theory's verdict (it could have been contradicted: a hold of +dc failing where k_path
    # is clearly positive): k_path clearly positive at the first equilibrium, not at the last
    th = s["paths"][0]["theory"]
    assert th["verdict"] == "passes", th
    assert th["k_path_first"] > 2 * th["k_noise"] >= 2 * th["k_path_last"] > -np.inf
    assert th["k_path_ratio"] == th["k_path_last"] / th["k_path_first"]
    assert th["c_cross"] <= runs[1]["c_peak"] and th["overshoot_c"] >= 0
    assert th["c_cross_band"][0] <= th["c_cross"] <= th["c_cross_band"][1]
    # the growth against the work of the held step (it could fail both ways): the settling run
    # never gives back what the step put in, the failing run gives back more than it
    below, past = runs
    assert below["ke_w2ext_max"] < 1 and not below["released"]
    assert past["released"] and past["ke_w2ext_max"] >= RELEASE and past["t_release"] > 0
    assert below["ke_end_over_bound"] <= 1 < 1e3 < past["ke_end_over_bound"]
    # the anatomy against its noise: each switch's state held with no change of load (history's
    # baseline rows): the raw count (d f . d l < 0) is mostly noise, the thresholded one is not
    # (dem.anatomy.UNSTABLE_TAU): the failing run's unstable contacts far exceed the baseline's
    for r in runs:
        b = [x for x in hist if x["switch"] == f"baseline_{r['switch']}"]
        assert b and all(x["c_target"] == r["c_switch"] for x in b)
        assert r["unstable_noise_max"] == max(x["n_unstable"] for x in b[1:])
        assert r["unstable_raw_noise_max"] == max(x["n_unstable_raw"] for x in b[1:])
        assert r["n_unstable_excess"] == r["n_unstable_max"] - r["unstable_noise_max"]
        assert r["unstable_raw_noise_max"] > 10 * max(r["unstable_noise_max"], 1)
    assert past["n_unstable_excess"] > 10 * max(below["n_unstable_excess"], 1)
    assert np.isfinite(past["t_onset"])
    # only the states the switches started from are kept
    assert sorted(p.name for p in (out / "rest").iterdir()) == sorted(
        f"R-2_f0.9_{r['switch']}.npz" for r in runs)
    # the figures say what their titles say (issue 32, tests/_figures.py): the strain figure's
    # line styles as its title gives them; the ledger's symlog axes without labels piled at 0,
    # its legend drawn and off the curves; the anatomy's arrows clipped to their own panel
    fig = caught["fig_burst_strain.png"]
    (ax,) = fig.axes
    assert "solid: below, dashed: past" in ax.get_title() and "lateral strain (dotted)" in ax.get_title()
    assert F.line_styles(ax, "below", "axial") == {"-"}
    assert F.line_styles(ax, "past", "axial") == {"--"}
    assert F.line_styles(ax, "lateral") == {":"}
    assert F.overlapping_texts(fig) == [] and F.undrawn_legend_entries(fig) == []
    F.assert_readable(caught["fig_burst_ledger.png"])
    fig = caught["fig_burst_anatomy.png"]
    assert F.overlapping_texts(fig) == []
    for ax in fig.axes:
        for q in ax.collections:
            if type(q).__name__ == "Quiver":
                assert q.get_clip_on() and q.get_clip_box() is ax.bbox


def _same_files(a, b):
    """Every file of the burst folder ``a`` the same bytes as ``b``'s but the wall times
    (probes.csv's column, summary.json's and burst_runs.jsonl's keys) and command.json (the
    command line); the same file names."""
    import os

    def files(d):
        return sorted(os.path.relpath(os.path.join(r, f), d) for r, _, fs in os.walk(d)
                      for f in fs)

    def strip(o):
        if isinstance(o, dict):
            return {k: strip(v) for k, v in o.items() if not k.endswith("wall_time")}
        return [strip(v) for v in o] if isinstance(o, list) else o

    assert files(a) == files(b)
    for f in files(a):
        x, y = (a / f).read_bytes(), (b / f).read_bytes()
        if f == "command.json":
            continue
        if f == "probes.csv":
            k = PROBE_COLUMNS.index("wall_time")
            x, y = ([line.split(",")[:k] + line.split(",")[k + 1:] for line in z.decode().split("\n")]
                    for z in (x, y))
        elif f == "summary.json":
            x, y = strip(json.loads(x)), strip(json.loads(y))
        elif f == "burst_runs.jsonl":
            x, y = ([strip(json.loads(line)) for line in z.splitlines()] for z in (x, y))
        assert x == y, f


def test_two_workers_write_the_files_of_one(burst_300, biaxial_300, tmp_path, capsys):
    # the probes, the below run and the baselines beside the staircase, in the pool's other
    # process, as their states come: the same files, row for row, as one worker running them
    # one after another (the probes after the staircase)
    from dem.__main__ import main
    out = tmp_path / "burst"
    main(_burst_args(biaxial_300, out, 2))
    err = capsys.readouterr().err
    # the staircase went on while the probes ran: a probe finished before the search ended
    assert err.index("probe at relaxed_start") < err.index("rest search:")
    _same_files(out, burst_300[0])


def test_resume_keeps_the_finished_runs_and_refuses_another_folder(biaxial_300, tmp_path,
                                                                     capsys, monkeypatch):
    # a run interrupted after its path and relaxations resumes with them (the log says so and
    # runs only the holds), to the same files; resumed on two workers and interrupted there
    # once a probe is journaled, what had finished is not run again; a folder of other options
    # is refused with one line before anything is computed
    from dem.__main__ import main
    from dem.burst.journal import _Journal
    out = tmp_path / "burst"
    args = ["burst", "--biaxial", str(biaxial_300), "--out", str(out), "--workers", "1",
            "--threads", "1", "--max-steps", "200000", "--max-holds", "5"]
    two = args[:6] + ["2"] + args[7:]                         # --workers 2
    import dem.burst.stairs as b
    real = b.hold
    calls = {"n": 0}

    def flaky(*a, **k):               # interrupted in the staircase's fourth hold
        calls["n"] += 1
        if calls["n"] == 4:
            raise KeyboardInterrupt
        return real(*a, **k)

    b.hold = flaky
    try:
        with pytest.raises(SystemExit) as e:         # the CLI's Ctrl-C: one line, exit 130
            main(args)
        assert e.value.code == 130
    finally:
        b.hold = real
    assert (out / "burst_runs.jsonl").exists()
    journal = out / "rest" / "R-2_f0.9.jsonl"
    with open(journal, "a") as fh:
        fh.write('{"kind": "ho')                              # a torn last line
    capsys.readouterr()
    kept, add = [], _Journal.add_probe

    def add_then_stop(self, p):       # the pool's run stopped once its first probe is journaled
        add(self, p)
        kept.append(p.key)
        raise KeyboardInterrupt

    with monkeypatch.context() as mp:
        mp.setattr(_Journal, "add_probe", add_then_stop)
        with pytest.raises(SystemExit) as e:
            main(two + ["--resume"])
        assert e.value.code == 130 and len(kept) == 1
    err = capsys.readouterr().err
    main(two + ["--resume"])
    err += capsys.readouterr().err
    assert "resumed from" in err and "1 paths finished" in err
    assert "state relaxed at fixed strain" not in err and "hold 0:" not in err
    assert err.count("stair hold 3:") == 1 and f"probe at {kept[0]}:" not in err
    assert len(io.read_csv(out / "stairs.csv")[1]) == 5
    whole = tmp_path / "whole"
    main([str(whole) if a == str(out) else a for a in args])  # the same, uninterrupted
    _same_files(out, whole)
    capsys.readouterr()
    code, err = _run(args + ["--resume", "--dc", "200"], capsys)
    assert code == 2 and len(err) == 1 and "--resume" in err[0], err


@pytest.mark.parametrize("args,option,words", [
    (["--ratios", "0"], "--ratios", "R = 0"),
    (["--ratios", "-2,nan"], "--ratios", "finite"),
    (["--ratios", "0.5"], "--ratios", "R > 0"),
    (["--ratios", "-2,x"], "--ratios", "numbers"),
    (["--dc", "-1"], "--dc", ">= 0"),
    (["--start-fractions", "0.5"], "--start-fractions", "not saved"),
    (["--below-rise", "1"], "--below-rise", "< 1"),
    (["--below-rise", "0"], "--below-rise", "0 <"),
    (["--wall-mass", "0"], "--wall-mass", "> 0"),
    (["--wall-mass", "-5"], "--wall-mass", "> 0"),
    (["--wall-mass", "nan"], "--wall-mass", "finite"),
    (["--wall-mass", "inf"], "--wall-mass", "finite"),
    (["--relax-max-steps", "1000"], "--relax-max-steps", "two equilibrium windows"),
    (["--hold", "spring"], "--hold", "dead_load"),
    (["--workers", "0"], "--workers", "1 <= value"),
])
def test_bad_input_is_one_line_exit_2_nothing_written(biaxial_300, tmp_path, capsys, args,
                                                      option, words):
    out = tmp_path / "out"
    code, err = _run(["burst", "--biaxial", str(biaxial_300), "--out", str(out)] + args, capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("error:"), err
    assert option in err[0] and words in err[0], err
    assert not out.exists()


class _Reached(Exception):
    """Raised where run_burst starts its work, its options checked (no file written yet)."""


def _stop_at_the_work(monkeypatch):
    import dem.burst.command as command

    def reached(*a, **k):
        raise _Reached
    monkeypatch.setattr(command, "checkpoint_header", reached)


def test_the_size_rule_is_the_samples_own_on_the_command_line(biaxial_300, tmp_path, capsys,
                                                              monkeypatch):
    """The relaxation's cap against the sample's own size (issue 33): 30000 steps are two
    equilibrium windows at 300 disks (22000), not at 1000 (40000): accepted, by the command line
    and by run_burst after it; 20000 are not: refused in one line, exit 2, before any state is
    loaded (the disk count is read from the biaxial test's summary.json) or anything written."""
    from dem import io as dio
    loaded = []
    real_load = dio.load_state
    monkeypatch.setattr(dio, "load_state", lambda *a, **k: loaded.append(a) or real_load(*a, **k))
    out = tmp_path / "out"
    code, err = _run(["burst", "--biaxial", str(biaxial_300), "--out", str(out),
                      "--relax-max-steps", "20000"], capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("error: --relax-max-steps 20000"), err
    assert ">= 22000" in err[0] and "two equilibrium windows at 300 disks" in err[0], err
    assert not loaded and not out.exists()
    _stop_at_the_work(monkeypatch)
    from dem.__main__ import main
    with pytest.raises(_Reached):
        main(["burst", "--biaxial", str(biaxial_300), "--out", str(out), "--workers", "1",
              "--threads", "1", "--relax-max-steps", "30000"])
    assert "error" not in capsys.readouterr().err and not out.exists()


def test_the_size_rule_is_the_samples_own_in_run_burst(biaxial_300, tmp_path, monkeypatch):
    """run_burst (the cross-check's call, unchecked before it) checks its options by the
    command line's rule: the same ranges, the same rule of the sample's size, before any state
    is loaded or file written."""
    from dem.burst import BurstOptions, run_burst
    out = tmp_path / "out"
    for bad, words in ((BurstOptions(relax_max_steps=20000), "relax_max_steps >= 22000 (two "
                        "equilibrium windows at 300 disks"), (BurstOptions(rate=11.0), "rate <= 10"),
                       (BurstOptions(relax_max_steps=1000), "two equilibrium windows")):
        with pytest.raises(ValueError) as e:
            run_burst(biaxial_300, out, [-2.0], [0.9], bad, workers=1, verbose=False)
        assert words in str(e.value) and "\n" not in str(e.value), str(e.value)
    assert not out.exists()
    _stop_at_the_work(monkeypatch)
    with pytest.raises(_Reached):
        run_burst(biaxial_300, out, [-2.0], [0.9], BurstOptions(relax_max_steps=30000),
                  workers=1, verbose=False)
    assert not out.exists()


def test_the_size_rule_alone():
    """BurstOptions: its ranges without the size (validate()), the rule of the size once it is
    known (check_size, validate(n)): no size is assumed."""
    from dem.burst import BurstOptions
    o = BurstOptions(relax_max_steps=30000)
    assert o.validate() is o and o.check_size(300) is o and o.validate(300) is o
    for call in (lambda: o.check_size(1000), lambda: o.validate(1000)):
        with pytest.raises(ValueError, match=r"relax_max_steps >= 40000 \(two equilibrium "
                                             r"windows at 1000 disks"):
            call()
    with pytest.raises(ValueError, match="two equilibrium windows of the sample"):
        BurstOptions(relax_max_steps=1999).validate()     # below two windows of any sample
    assert BurstOptions(relax_max_steps=2000).validate(1).relax_max_steps == 2000


def _refused(field, **kw):
    """The message of BurstOptions(**kw).validate() if it refuses ``field`` (its message starts
    "field="), else None (accepted, or another field refused)."""
    from dem.burst import BurstOptions
    try:
        BurstOptions(**kw).validate()
    except ValueError as e:
        if str(e).startswith(f"{field}="):
            return str(e)
    return None


def _ends(field, t):
    """(value, refused?) at and just beyond each end of the vocabulary's term ``t``."""
    step = ((lambda v, to: v + (1 if to > v else -1)) if t.kind == "int" else
            (lambda v, to: math.nextafter(v, to)))
    out = []
    for end, is_open, outward in ((t.lo, t.lo_open, -math.inf), (t.hi, t.hi_open, math.inf)):
        if end is not None:
            out += [(end, is_open), (step(end, outward), True), (step(end, -outward), False)]
    return out


def test_the_ranges_of_the_shared_options_are_the_vocabularys():
    """Issue 33, one validation per value: a BurstOptions field whose option is a term of the
    vocabulary with a range (--rate, --path-strain, --dc; --max-steps, by dem.settle's rule)
    is refused and accepted by validate exactly at the term's ends, and the message says the
    term's range."""
    from common.options import VOCABULARY, term_of
    from dem.burst import BurstOptions
    shared = {}
    for f in BurstOptions._fields:
        ts = [t for t in VOCABULARY.values() if f"BurstOptions.{f}" in t.fields]
        if ts:
            assert ts == [term_of("BurstOptions", f)]
            if ts[0].bounded:
                shared[f] = ts[0]
        else:
            with pytest.raises(KeyError):       # no guess by name: strain_norm is not --strain-norm
                term_of("BurstOptions", f)
    assert {"rate", "path_strain", "dc"} <= set(shared), shared
    for f, t in shared.items():
        for v, refused in _ends(f, t):
            kw = {f: v}
            if f == "path_strain" and v > 0:      # record_strain < path_strain, checked after it
                kw["record_strain"] = min(5e-6, v / 2)
            msg = _refused(f, **kw)
            assert (msg is not None) == refused, (f, v, msg)
            if msg and f in ("rate", "path_strain", "dc"):
                assert msg.endswith(f"allowed range: {t.range_text().replace('value', f)}"
                                    + (f" [{t.unit}]" if t.unit not in ("-", None) else "")), msg


def test_validate_reads_the_vocabulary_it_writes_no_copy(monkeypatch):
    """The ranges of --rate, --path-strain and --dc are read from the vocabulary at validate:
    another term's range, narrower or wider, is followed (a copy written in validate would keep
    refusing or accepting by its own)."""
    import dataclasses
    import common.options as O
    cases = {"--rate": ("rate", {"hi": 5.0}, 6.0, {"hi": 20.0}, 15.0),
             "--path-strain": ("path_strain", {"hi": 0.2}, 0.3, {"hi": 0.9}, 0.7),
             "--dc": ("dc", {"lo": 10.0}, 5.0, {"lo": -10.0}, -5.0)}
    for name, (field, narrow, out, wide, now_in) in cases.items():
        term = O.VOCABULARY[name]
        assert _refused(field, **{field: out}) is None and _refused(field, **{field: now_in})
        monkeypatch.setitem(O.VOCABULARY, name, dataclasses.replace(term, **narrow))
        msg = _refused(field, **{field: out})
        assert msg and O.VOCABULARY[name].range_text().replace("value", field) in msg, (name, msg)
        monkeypatch.setitem(O.VOCABULARY, name, dataclasses.replace(term, **wide))
        assert _refused(field, **{field: now_in}) is None, name
        monkeypatch.setitem(O.VOCABULARY, name, term)


def test_a_state_of_other_parameters_is_refused(biaxial_300, tmp_path, capsys):
    other = tmp_path / "bx"
    shutil.copytree(biaxial_300, other)
    st, meta = io.load_state(other / "states" / "state_f0.900.npz")
    io.save_state(other / "states" / "state_f0.900.npz",
                  st._replace(params=st.params.replace(phi_g=30.0)), meta)
    out = tmp_path / "out"
    code, err = _run(["burst", "--biaxial", str(other), "--out", str(out)], capsys)
    assert code == 2 and len(err) == 1 and "other parameters" in err[0], err
    # and a --params file that is not the states' own
    pfile = tmp_path / "p.json"
    pfile.write_text(json.dumps(st.params.replace(density=2000.0).to_dict()))
    code, err = _run(["burst", "--biaxial", str(biaxial_300), "--out", str(out), "--params",
                      str(pfile)], capsys)
    assert code == 2 and len(err) == 1 and "--params" in err[0] and "density" in err[0], err
    assert not out.exists()


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_is_one_line(biaxial_300, tmp_path, sig, code):
    from tests._interrupt import interrupt_after
    rc, err = interrupt_after(["dem", "burst", "--biaxial", str(biaxial_300), "--out",
                               str(tmp_path / "o"), "--workers", "1", "--threads", "1"],
                              "[burst] 1 proportional", sig=sig)
    assert rc == code
    assert len(err) == 1 and err[0].startswith("interrupted") and "dem burst" in err[0], err
