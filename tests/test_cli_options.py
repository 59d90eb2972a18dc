"""Every subcommand's parser, walked: exact options, the same run options everywhere.

The CLIs (point, hmodel, fem, dem and the cross-check above them) build their parsers with ``common.options.Parser``: no prefix matching (argparse
would take ``--sigma`` for ``--sigma2`` and run), an unknown option refused by the subcommand
that got it, naming the options it resembles and that subcommand's own ``--help``. Commands that
show progress take ``--quiet``; the long DEM commands take ``--workers``, ``--resume`` and
``--scheduler`` with the same meaning. Parsing computes and writes nothing.
"""
from __future__ import annotations

import argparse

import pytest

from common.options import OptionError

CLIS = ("point", "hmodel", "fem", "dem", "crosscheck")

# commands that print no progress (a file is written at once, or only figures are printed)
NO_PROGRESS = {("point", "params"), ("hmodel", "params"), ("dem", "params"), ("dem", "bench")}

# the DEM commands that spread runs over processes or a cluster, and resume an interrupted run
# (the cross-check's DEM part among them: python -m crosscheck, one command)
LONG_DEM = [("dem", "probes"), ("dem", "domain"), ("dem", "burst"), ("dem", "calibrate"),
            ("crosscheck", None)]
RUN_OPTIONS = ("--workers", "--resume", "--scheduler")
# PENDING: options a command is to get on another branch; remove an entry once it is there (the
# test below fails as a reminder when it appears). None pending now.
PENDING = set()


def build(module):
    if module == "point":
        from point.cli import build_parser
    elif module == "hmodel":
        from hmodel.cli import build_parser
    elif module == "fem":
        from fem.__main__ import build_parser
    elif module == "crosscheck":
        from crosscheck.__main__ import build_parser
    else:
        from dem.__main__ import build_parser
    return build_parser()


def subcommands(parser):
    """name -> parser of every subcommand; {None: parser} for a command without subcommands
    (python -m crosscheck)."""
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not actions:
        return {None: parser}
    (action,) = actions
    return action.choices


def _words(name):
    """The subcommand's word of an argv: none for a command without subcommands."""
    return [] if name is None else [name]


def _command(module, name):
    """"dem biaxial", "crosscheck": the command as the vocabulary's former names list it."""
    return " ".join([module, *_words(name)])


def _prog(module, name):
    return f"python -m {_command(module, name)}"


ALL = [(m, name) for m in CLIS for name in subcommands(build(m))]


def _required(sub):
    """A value for every required option of ``sub`` (all are strings: files and folders)."""
    argv = []
    for a in sub._actions:
        if a.required and a.option_strings:
            argv += [a.option_strings[0], "x"]
    return argv


@pytest.mark.parametrize("module", CLIS)
def test_every_parser_is_exact(module):
    parser = build(module)
    assert parser.allow_abbrev is False
    for name, sub in subcommands(parser).items():
        assert sub.allow_abbrev is False, f"{_prog(module, name)} takes abbreviations"


@pytest.mark.parametrize("module,name", ALL)
def test_abbreviations_are_refused_naming_the_option(module, name):
    """Every proper prefix (3 characters or more) of every option of the subcommand that is not
    an option itself: refused, naming the options it abbreviates and the subcommand's --help."""
    parser = build(module)
    sub = subcommands(parser)[name]
    options = set(sub._option_string_actions)
    checked = 0
    for option in sorted(o for o in options if o.startswith("--")):
        for k in range(3, len(option)):
            prefix = option[:k]
            if prefix in options:
                continue
            with pytest.raises(OptionError) as e:
                parser.parse_args([*_words(name), *_required(sub), prefix, "1"])
            msg = str(e.value)
            assert f"no option {prefix} " in msg and "did you mean" in msg and option in msg, msg
            assert msg.endswith(f"(see {_prog(module, name)} --help)"), msg
            checked += 1
    assert checked > 0


@pytest.mark.parametrize("module,name", ALL)
def test_quiet_on_every_command_with_progress(module, name):
    sub = subcommands(build(module))[name]
    has = "--quiet" in sub._option_string_actions
    if (module, name) in NO_PROGRESS:
        assert not has, f"{_prog(module, name)} shows no progress: a --quiet means nothing"
        return
    assert has, f"{_prog(module, name)} shows progress and has no --quiet"
    q = sub._option_string_actions["--quiet"]
    assert isinstance(q, argparse._StoreTrueAction) and q.default is False
    assert q.help.startswith("no progress lines on stderr")     # the one helper, add_quiet


@pytest.mark.parametrize("module,name", LONG_DEM)
def test_run_options_on_every_long_dem_command(module, name):
    sub = subcommands(build(module))[name]
    acts = sub._option_string_actions
    for option in RUN_OPTIONS:
        if (name, option) in PENDING:
            assert option not in acts, (f"{_command(module, name)} has {option} now: remove it "
                                        "from PENDING in this test")
            continue
        assert option in acts, f"{_prog(module, name)} has no {option}"
    if "--workers" in acts:
        w = acts["--workers"]
        assert w.default is None
        for bad in ("0", "-1", "1.5"):
            with pytest.raises(argparse.ArgumentTypeError):
                w.type(bad)
        assert w.type("1") == 1 and w.type("4") == 4
        assert "process" in w.help
    if "--resume" in acts:
        assert isinstance(acts["--resume"], argparse._StoreTrueAction)
        assert acts["--resume"].default is False
    if "--scheduler" in acts:
        s = acts["--scheduler"]
        assert s.default is None and s.type is None and "scheduler address" in s.help


def test_fit_dem_parser_is_exact_with_quiet(monkeypatch):
    """`python -m crosscheck.fit` (formerly `python -m dem.crosscheck_fit`; one command, no
    subcommands) follows the same rules."""
    import crosscheck.fit.__main__ as fd
    import common.options as opt
    seen = {}
    monkeypatch.setattr(opt, "run_cli", lambda parser, *a, **k: seen.setdefault("parser", parser) and 0)
    fd.main([])
    parser = seen["parser"]
    assert parser.allow_abbrev is False and "--quiet" in parser._option_string_actions
    with pytest.raises(OptionError, match=r"no option --star .*did you mean --starts\?"):
        parser.parse_args(["--star", "2"])


def test_pending_run_options_are_dem_burst_only():
    assert {name for name, _ in PENDING} <= {"burst"}


# the newcomer's mistakes (issues 26, 32), each one line naming what to write instead, exit 2
MISTAKES = [
    (["fem", "biaxial", "--sigma", "100000", "--out", "OUT"], "did you mean --sigma2?",
     "python -m fem biaxial --help"),
    (["hmodel", "burst", "--ratio", "-2", "--out", "OUT"], "did you mean --ratios?",
     "python -m hmodel burst --help"),
    (["hmodel", "biaxial", "--eps-max", "0.1", "--out", "OUT"], "did you mean --eps1-max?",
     "python -m hmodel biaxial --help"),
    (["dem", "biaxial", "--eps-max", "0.02", "--out", "OUT"], "did you mean --eps1-max?",
     "python -m dem biaxial --help"),
    (["dem", "biaxial", "--confining", "2e5", "--out", "OUT"], "did you mean --sigma2?",
     "python -m dem biaxial --help"),
    (["dem", "calibrate", "--confining", "2e5", "--out", "OUT"], "did you mean --sigma2?",
     "python -m dem calibrate --help"),
    (["dem", "biaxial", "--friction", "30", "--out", "OUT"], "did you mean --phi-g?",
     "python -m dem biaxial --help"),
    (["hmodel", "probes", "--eta", "1.0", "--out", "OUT"], "did you mean --eta-a?",
     "python -m hmodel probes --help"),
    (["hmodel", "probes", "--norm", "1e-6", "--out", "OUT"], "did you mean --strain-norm?",
     "python -m hmodel probes --help"),
    (["hmodel", "probes", "--sigma-norm", "2e3", "--out", "OUT"], "did you mean --stress-norm?",
     "python -m hmodel probes --help"),
    (["dem", "probes", "--norm", "2e3", "--state", "S", "--out", "OUT"],
     "did you mean --stress-norm?", "python -m dem probes --help"),
    (["crosscheck", "--skip-dem", "--out", "OUT"], "did you mean --no-dem?",
     "python -m crosscheck --help"),
    (["crosscheck", "--burst-fractions", "0.9", "--out", "OUT"],
     "did you mean --start-fractions?", "python -m crosscheck --help"),
    (["crosscheck", "--burst-ratios", "-2", "--out", "OUT"], "did you mean --ratios?",
     "python -m crosscheck --help"),
    (["dem", "crosscheck", "--out", "OUT"], "moved to python -m crosscheck",
     "python -m crosscheck --help"),
    (["dem", "brust", "--out", "OUT"], "no command 'brust': did you mean burst?",
     "python -m dem --help"),
    (["hmodel", "biaxal", "--out", "OUT"], "no command 'biaxal': did you mean biaxial?",
     "python -m hmodel --help"),
    (["fem", "--quiet", "biaxial", "--out", "OUT"], "write it after 'biaxial'",
     "python -m fem --help"),
    (["hmodel", "domain", "--sigma2", "100e3", "200e3", "--out", "OUT"],
     "unexpected argument '200e3'", "python -m hmodel domain --help"),
    (["dem", "probes", "--out", "OUT"], "required: --state", "python -m dem probes --help"),
    (["fem", "biaxial", "--nx", "10.5", "--out", "OUT"], "not an integer",
     "python -m fem biaxial --help"),
    (["hmodel", "probes", "--out", "OUT", "--n-dir"], "expected one argument",
     "python -m hmodel probes --help"),
    (["dem", "biaxial", "--sigma2", "200kPa", "--out", "OUT"], "is not a number",
     "python -m dem biaxial --help"),
    (["hmodel", "biaxial", "--eps1-max", "0.01"], "required: --out",
     "python -m hmodel biaxial --help"),
    (["point", "biaxial", "--model", "drucker", "--out", "OUT"],
     "--model 'drucker': did you mean drucker-prager?", "python -m point biaxial --help"),
    (["point", "probes", "--shear", "4e7", "--out", "OUT"],
     "did you mean --shear-modulus?", "python -m point probes --help"),
]


def _main(module):
    if module == "point":
        from point.cli import main
    elif module == "hmodel":
        from hmodel.cli import main
    elif module == "fem":
        from fem.__main__ import main
    elif module == "crosscheck":
        from crosscheck.__main__ import main
    else:
        from dem.__main__ import main
    return main


@pytest.mark.parametrize("argv,says,help_of", MISTAKES, ids=[" ".join(m[0][:3]) for m in MISTAKES])
def test_newcomers_mistakes(argv, says, help_of, tmp_path, capsys):
    out = tmp_path / "out"
    argv = [str(out) if a == "OUT" else str(tmp_path / "s.npz") if a == "S" else a for a in argv]
    try:
        code = _main(argv[0])(argv[1:])
    except SystemExit as e:          # python -m dem exits with its code
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert says in err[0] and err[0].endswith(f"(see {help_of})"), err[0]
    assert not out.exists()


# -- one vocabulary (issue 32) ----------------------------------------------------------------
def _options(sub):
    """(option string, action) of every option of ``sub`` but --help (each action once, by its
    first option string)."""
    return [(a.option_strings[0], a) for a in sub._actions
            if a.option_strings and a.option_strings[0] not in ("-h", "--help")]


@pytest.mark.parametrize("module,name", ALL)
def test_every_option_is_in_the_vocabulary_with_help_unit_and_default(module, name):
    """The parsers are built from common.options.VOCABULARY: every option is a term of it, its
    help says what it is, the unit of a quantity in brackets, and its default (or "required")."""
    from common.options import VOCABULARY
    sub = subcommands(build(module))[name]
    bad = []
    for option, a in _options(sub):
        t = VOCABULARY.get(option)
        if t is None:
            bad.append(f"{option}: not in the vocabulary")
            continue
        h = a.help or ""
        if not h.startswith(t.help):
            bad.append(f"{option}: no help from the vocabulary ({h!r})")
        if t.unit and f"[{t.unit}]" not in h:
            bad.append(f"{option}: a quantity without its unit [{t.unit}] in the help")
        if ("; default " not in h) != a.required or ("; required" in h) != a.required:
            bad.append(f"{option}: the help does not say the default (or required): {h!r}")
        if a.default is None and not a.required and "; default None" in h:
            bad.append(f"{option}: 'default None' says nothing: {h!r}")
    assert not bad, f"{_prog(module, name)}:\n" + "\n".join(bad)


def test_every_quantity_has_a_unit_and_every_switch_is_positive_or_no():
    from common.options import VOCABULARY
    for t in VOCABULARY.values():
        if t.kind in ("real", "reals"):
            assert t.unit, f"{t.name} is a quantity with no unit ('-' if dimensionless)"
        # --allow-soft, like --force, permits what is refused otherwise (dem.regime);
        # --stop-decided-runs, like --full, turns on what is off by default (dem calibrate)
        if t.kind == "flag" and t.name not in ("--quiet", "--force", "--resume", "--full",
                                               "--busy-core", "--check-tangent",
                                               "--allow-soft", "--stop-decided-runs"):
            assert t.name.startswith("--no-"), f"{t.name}: a negative switch is --no-..."
        assert not t.name.startswith("--skip"), t.name


# the names the issue retired, in no command any more
RETIRED = ("--confining", "--eps-max", "--norm", "--sigma-norm", "--friction", "--skip-dem",
           "--burst-fractions", "--burst-ratios", "--compaction-friction")


@pytest.mark.parametrize("module,name", ALL)
def test_retired_names_are_gone(module, name):
    sub = subcommands(build(module))[name]
    opts = set(sub._option_string_actions)
    assert not opts & set(RETIRED), f"{_prog(module, name)}: {sorted(opts & set(RETIRED))}"
    assert not [o for o in opts if o.startswith("--skip")]
    if (module, name) == ("hmodel", "probes"):
        assert "--eta" not in opts and "--eta-a" in opts
    if module == "hmodel":
        assert "--n" not in opts, "hmodel's --n (directions) is --n-probes; --n is the disks"


def test_the_issues_options_where_the_issue_says():
    """Done when: --sigma2 and --eps1-max on hmodel biaxial, fem biaxial, dem biaxial and dem
    calibrate; --eta-a on hmodel probes and dem biaxial; one meaning of --d-eps1 (the drained
    path's), the proportional paths' --path-d-eps1 on both burst commands that have paths of
    steps; --phi-g for the grain friction angle in the three parts."""
    want = {("hmodel", "biaxial"): ("--sigma2", "--eps1-max", "--phi-g"),
            ("fem", "biaxial"): ("--sigma2", "--eps1-max", "--phi-g"),
            ("dem", "biaxial"): ("--sigma2", "--eps1-max", "--eta-a", "--phi-g"),
            ("dem", "calibrate"): ("--sigma2", "--eps1-max", "--phi-g"),
            ("hmodel", "probes"): ("--eta-a", "--strain-norm", "--stress-norm"),
            ("dem", "probes"): ("--stress-norm",),
            ("hmodel", "burst"): ("--d-eps1", "--path-d-eps1"),
            ("fem", "burst"): ("--d-eps1", "--path-d-eps1"),
            ("crosscheck", None): ("--no-dem", "--start-fractions", "--ratios")}
    for (module, name), options in want.items():
        acts = subcommands(build(module))[name]._option_string_actions
        for o in options:
            assert o in acts, f"{_prog(module, name)} has no {o}"
    for module, name in ALL:
        acts = subcommands(build(module))[name]._option_string_actions
        if "--d-eps1" in acts:
            assert acts["--d-eps1"].help.startswith("axial strain step of the drained path")


@pytest.mark.parametrize("module,name", ALL)
def test_the_out_rule(module, name):
    """--out is required by every command that writes (a folder with --force beside it; the
    file of `params`); `dem bench` writes nothing but its cache."""
    acts = subcommands(build(module))[name]._option_string_actions
    if (module, name) == ("dem", "bench"):
        assert "--out" not in acts
        return
    assert acts["--out"].required and acts["--out"].default is None
    assert ("--force" in acts) == (name != "params")


def test_every_former_name_says_its_new_one():
    """Every former name of the vocabulary, in every command that has its new name: one line
    naming the new name."""
    from common.options import VOCABULARY
    checked = 0
    for t in VOCABULARY.values():
        for old, commands in t.old:
            for module, name in ALL:
                if commands and _command(module, name) not in commands:
                    continue
                parser = build(module)
                sub = subcommands(parser)[name]
                if t.name not in sub._option_string_actions:
                    continue
                argv = [*_words(name), *_required(sub), old] + (["1"] if t.kind != "flag" else [])
                with pytest.raises(OptionError) as e:
                    parser.parse_args(argv)
                msg = str(e.value)
                assert f"no option {old} (renamed {t.name}" in msg and \
                    f"did you mean {t.name}" in msg, (module, name, msg)
                checked += 1
    assert checked >= 20


@pytest.mark.parametrize("module", ("fem", "dem", "hmodel", "point"))
def test_top_help_describes_the_commands(module, capsys):
    parser = build(module)
    with pytest.raises(SystemExit):
        parser.parse_args(["--help"])
    out = capsys.readouterr().out
    assert "thin" not in out and "argparse" not in out
    for name, sub in subcommands(parser).items():
        assert name in out
    assert "COMMAND --help" in out and "--out is required" in out


def test_record_errors_name_the_option():
    """A value a record refuses is named by its option (the record's field never shows)."""
    from common.options import record_error
    from dem.burst import BurstOptions
    from dem.params import DemParams
    from dem.probes import ProbeOptions
    with pytest.raises(ValueError) as e:
        ProbeOptions(norm=-1.0).validate()
    assert str(record_error(e.value, "ProbeOptions")).startswith("--stress-norm -1.0")
    with pytest.raises(ValueError) as e:
        DemParams(phi_g=95.0)
    assert str(record_error(e.value, "DemParams")).startswith("--phi-g 95.0")
    with pytest.raises(ValueError) as e:
        BurstOptions(rate=0.0).validate()
    assert str(record_error(e.value, "BurstOptions")).startswith("--rate 0.0")
