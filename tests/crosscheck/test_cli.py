"""The cross-check's commands moved above the three parts (issue 33): `python -m dem crosscheck`
is `python -m crosscheck`, `python -m dem.crosscheck_fit` is `python -m crosscheck.fit`; the
former commands answer in one line where they moved, exit 2, nothing written. (The bad input of
`python -m crosscheck`: tests/dem/test_bad_input.py and test_params_file.py, as before the move;
its parser walked with the other CLIs': tests/test_cli_options.py.)"""
import subprocess
import sys

import pytest


@pytest.mark.parametrize("argv", [["crosscheck", "--out", "OUT"],
                                  ["crosscheck", "--full", "--resume", "--out", "OUT"],
                                  ["crosscheck", "--help"]])
def test_dem_crosscheck_says_where_it_moved(argv, tmp_path, capsys):
    from dem.__main__ import main
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as e:
        main([str(out) if a == "OUT" else a for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and err == ["error: python -m dem crosscheck moved to python -m "
                                         "crosscheck, with the same options (see python -m "
                                         "crosscheck --help)"], err
    assert not out.exists()


@pytest.mark.parametrize("module,new", [(["dem", "crosscheck"], "python -m crosscheck"),
                                        (["dem.crosscheck_fit"], "python -m crosscheck.fit")])
def test_the_former_commands_answer_in_one_line(module, new, tmp_path):
    """As typed: one line on stderr naming the new command, exit 2, nothing on stdout."""
    r = subprocess.run([sys.executable, "-m", *module, "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stdout == "", (r.stdout, r.stderr)
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith("error: python -m ") and f"moved to {new}," in line
    assert line.endswith(f"(see {new} --help)")
    assert not (tmp_path / "o").exists()


def test_the_new_commands_help(capsys):
    """`python -m crosscheck --help` names what it writes, the --out rule and the fit's command."""
    from crosscheck.__main__ import main
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    out = capsys.readouterr().out
    assert e.value.code == 0 and out.startswith("usage: python -m crosscheck ")
    assert "report.md" in out and "--out is required" in out and "python -m crosscheck.fit" in out


def test_a_folder_of_the_former_command_is_the_new_ones(tmp_path):
    """A run of `python -m dem crosscheck` (its command.json) is resumed by `python -m
    crosscheck` without --force; another command's folder is refused as before."""
    import json

    from common.options import OptionError, check_owner, folder_owner
    old, other = tmp_path / "old", tmp_path / "other"
    for d, command in ((old, "python -m dem crosscheck"), (other, "python -m dem biaxial")):
        d.mkdir()
        (d / "command.json").write_text(json.dumps({"command": command}))
    assert folder_owner(old) == "python -m crosscheck"
    check_owner(old, "python -m crosscheck")
    with pytest.raises(OptionError, match="the output folder of python -m dem biaxial"):
        check_owner(other, "python -m crosscheck")
