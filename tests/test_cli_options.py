"""Every subcommand's parser, walked: exact options, the same run options everywhere.

The three CLIs build their parsers with ``hmodel.options.Parser``: no prefix matching (argparse
would take ``--sigma`` for ``--sigma2`` and run), an unknown option refused by the subcommand
that got it, naming the options it resembles and that subcommand's own ``--help``. Commands that
show progress take ``--quiet``; the long DEM commands take ``--workers``, ``--resume`` and
``--scheduler`` with the same meaning. Parsing computes and writes nothing.
"""
from __future__ import annotations

import argparse

import pytest

from hmodel.options import OptionError

CLIS = ("hmodel", "fem", "dem")

# commands that print no progress (a file is written at once, or only figures are printed)
NO_PROGRESS = {("hmodel", "params"), ("dem", "params"), ("dem", "bench")}

# the DEM commands that spread runs over processes or a cluster, and resume an interrupted run
LONG_DEM = ("probes", "domain", "burst", "calibrate", "crosscheck")
RUN_OPTIONS = ("--workers", "--resume", "--scheduler")
# PENDING: options a command is to get on another branch; remove an entry once it is there (the
# test below fails as a reminder when it appears). None pending now.
PENDING = set()


def build(module):
    if module == "hmodel":
        from hmodel.cli import build_parser
    elif module == "fem":
        from fem.__main__ import build_parser
    else:
        from dem.__main__ import build_parser
    return build_parser()


def subcommands(parser):
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action.choices


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
        assert sub.allow_abbrev is False, f"python -m {module} {name} takes abbreviations"


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
                parser.parse_args([name, *_required(sub), prefix, "1"])
            msg = str(e.value)
            assert f"no option {prefix} " in msg and "did you mean" in msg and option in msg, msg
            assert msg.endswith(f"(see python -m {module} {name} --help)"), msg
            checked += 1
    assert checked > 0


@pytest.mark.parametrize("module,name", ALL)
def test_quiet_on_every_command_with_progress(module, name):
    sub = subcommands(build(module))[name]
    has = "--quiet" in sub._option_string_actions
    if (module, name) in NO_PROGRESS:
        assert not has, f"python -m {module} {name} shows no progress: a --quiet means nothing"
        return
    assert has, f"python -m {module} {name} shows progress and has no --quiet"
    q = sub._option_string_actions["--quiet"]
    assert isinstance(q, argparse._StoreTrueAction) and q.default is False
    assert q.help.startswith("no progress lines on stderr")     # the one helper, add_quiet


@pytest.mark.parametrize("name", LONG_DEM)
def test_run_options_on_every_long_dem_command(name):
    sub = subcommands(build("dem"))[name]
    acts = sub._option_string_actions
    for option in RUN_OPTIONS:
        if (name, option) in PENDING:
            assert option not in acts, (f"dem {name} has {option} now: remove it from PENDING "
                                        "in this test")
            continue
        assert option in acts, f"python -m dem {name} has no {option}"
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
    """`python -m dem.crosscheck_fit` (one command, no subcommands) follows the same rules."""
    import dem.crosscheck_fit as fd
    import hmodel.options as opt
    seen = {}
    monkeypatch.setattr(opt, "run_cli", lambda parser, *a, **k: seen.setdefault("parser", parser) and 0)
    fd.main([])
    parser = seen["parser"]
    assert parser.allow_abbrev is False and "--quiet" in parser._option_string_actions
    with pytest.raises(OptionError, match=r"no option --star .*did you mean --starts\?"):
        parser.parse_args(["--star", "2"])


def test_pending_run_options_are_dem_burst_only():
    assert {name for name, _ in PENDING} <= {"burst"}


# the newcomer's mistakes (issue 26), each one line naming what to write instead, exit 2
MISTAKES = [
    (["fem", "biaxial", "--sigma", "100000", "--out", "OUT"], "did you mean --sigma2?",
     "python -m fem biaxial --help"),
    (["hmodel", "burst", "--ratio", "-2", "--out", "OUT"], "did you mean --ratios?",
     "python -m hmodel burst --help"),
    (["hmodel", "biaxial", "--eps-max", "0.1", "--out", "OUT"], "did you mean --eps1-max?",
     "python -m hmodel biaxial --help"),
    (["dem", "biaxial", "--eps1-max", "0.02", "--out", "OUT"], "did you mean --eps-max?",
     "python -m dem biaxial --help"),
    (["fem", "--quiet", "biaxial", "--out", "OUT"], "write it after 'biaxial'",
     "python -m fem --help"),
    (["hmodel", "domain", "--sigma2", "100e3", "200e3", "--out", "OUT"],
     "unexpected argument '200e3'", "python -m hmodel domain --help"),
    (["dem", "probes", "--out", "OUT"], "required: --state", "python -m dem probes --help"),
    (["fem", "biaxial", "--nx", "10.5", "--out", "OUT"], "not an integer",
     "python -m fem biaxial --help"),
    (["hmodel", "probes", "--out", "OUT", "--n-dir"], "expected one argument",
     "python -m hmodel probes --help"),
    (["dem", "biaxial", "--confining", "200kPa", "--out", "OUT"], "is not a number",
     "python -m dem biaxial --help"),
]


def _main(module):
    if module == "hmodel":
        from hmodel.cli import main
    elif module == "fem":
        from fem.__main__ import main
    else:
        from dem.__main__ import main
    return main


@pytest.mark.parametrize("argv,says,help_of", MISTAKES, ids=[" ".join(m[0][:3]) for m in MISTAKES])
def test_newcomers_mistakes(argv, says, help_of, tmp_path, capsys):
    out = tmp_path / "out"
    argv = [str(out) if a == "OUT" else a for a in argv]
    try:
        code = _main(argv[0])(argv[1:])
    except SystemExit as e:          # python -m dem exits with its code
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert says in err[0] and err[0].endswith(f"(see {help_of})"), err[0]
    assert not out.exists()
