"""Folders and files that say whose they are (issue 32), and progress lines that read.

Every command that writes a folder records itself there (command.json); another command refuses
that folder in one line, exit 2, before writing anything, unless --force; the same command
writes (resumes or refuses) as before. Every file argument is checked for what it should be,
one line naming what was expected. An interrupted run names the files it wrote. The FE's
progress line labels its global checks; the material point's progress is plain lines, not a
``\\r`` bar, where stderr is not a terminal.
"""
from __future__ import annotations

import io
import json
import os

import pytest

from common.options import OWNER_FILE, Stage, folder_owner, snapshot

# the material point's biaxial test, small: 20 steps of 16 orientations (a second)
HBIAXIAL = ["biaxial", "--eps1-max", "0.002", "--d-eps1", "1e-4", "--n-dir", "16", "--quiet"]


def _hmodel(argv):
    from hmodel.cli import main
    return main(argv)


def _dem(argv):
    from dem.__main__ import main
    try:
        main(argv)
    except SystemExit as e:
        return e.code
    return 0


def _fem(argv):
    from fem.__main__ import main
    return main(argv)


def _one_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


@pytest.fixture(scope="module")
def hmodel_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("owner") / "hb"
    assert _hmodel([*HBIAXIAL, "--out", str(out)]) == 0
    return out


def test_a_folder_records_its_command(hmodel_folder):
    doc = json.loads((hmodel_folder / OWNER_FILE).read_text())
    assert doc["command"] == "python -m hmodel biaxial" and "--eps1-max" in doc["argv"]
    assert folder_owner(hmodel_folder) == "python -m hmodel biaxial"


@pytest.mark.parametrize("argv,run", [
    (["biaxial", "--n", "100"], _dem),            # the done-when
    (["probes", "--n-dir", "16"], _hmodel),
    (["biaxial", "--nx", "2", "--ny", "4"], _fem),
], ids=["dem biaxial", "hmodel probes", "fem biaxial"])
def test_another_command_refuses_the_folder_and_leaves_it(hmodel_folder, argv, run, capsys):
    before = snapshot(hmodel_folder)
    assert run([*argv, "--out", str(hmodel_folder)]) == 2
    line = _one_line(capsys)
    assert f"--out {hmodel_folder}: the output folder of python -m hmodel biaxial" in line
    assert "--force" in line
    assert snapshot(hmodel_folder) == before


def test_the_same_command_writes_again(hmodel_folder, capsys):
    assert _hmodel([*HBIAXIAL, "--out", str(hmodel_folder)]) == 0
    assert folder_owner(hmodel_folder) == "python -m hmodel biaxial"


def test_force_writes_and_says_over_what(tmp_path, capsys):
    out = tmp_path / "f"
    out.mkdir()
    (out / OWNER_FILE).write_text(json.dumps({"command": "python -m fem biaxial"}))
    assert _hmodel([*HBIAXIAL, "--out", str(out)]) == 2
    assert "the output folder of python -m fem biaxial" in _one_line(capsys)
    assert not (out / "biaxial.csv").exists()
    assert _hmodel([*HBIAXIAL, "--out", str(out), "--force"]) == 0
    doc = json.loads((out / OWNER_FILE).read_text())
    assert doc["command"] == "python -m hmodel biaxial"
    assert doc["written_over"] == "python -m fem biaxial"


def test_a_folder_from_before_command_json_is_known_by_its_params(tmp_path, capsys):
    """A folder written before this rule has no command.json: its params.json's note names the
    command (every command writes one)."""
    out = tmp_path / "old"
    out.mkdir()
    (out / "params.json").write_text(json.dumps({"model": "hmodel",
                                                 "note": "python -m fem biaxial; parameters: x"}))
    before = snapshot(out)
    assert _hmodel([*HBIAXIAL, "--out", str(out)]) == 2
    assert "the output folder of python -m fem biaxial" in _one_line(capsys)
    assert snapshot(out) == before


def test_a_refused_option_writes_no_record(tmp_path, capsys):
    out = tmp_path / "x"
    out.mkdir()
    assert _hmodel(["biaxial", "--eps1-max", "0.6", "--out", str(out)]) == 2
    _one_line(capsys)
    assert list(out.iterdir()) == []


# -- file arguments ------------------------------------------------------------------------------
@pytest.fixture
def summary_json(tmp_path):
    f = tmp_path / "summary.json"
    f.write_text(json.dumps({"outcome": "complete", "steps": [1, 2, 3],
                             "end": {"line": "x"}}, indent=1))
    return f


def test_a_state_that_is_no_state(summary_json, tmp_path, capsys):
    out = tmp_path / "p"
    assert _dem(["probes", "--state", str(summary_json), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert f"--state {summary_json}: not a DEM state" in line
    assert "an .npz written by python -m dem biaxial" in line and "pickle" not in line
    assert _dem(["probes", "--state", str(tmp_path), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "is a folder" in line and "DEM state file" in line
    assert not out.exists()


def test_a_biaxial_folder_that_is_none(tmp_path, hmodel_folder, capsys):
    out = tmp_path / "b"
    assert _dem(["burst", "--biaxial", str(tmp_path / "nope"), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "no such folder" in line and "states.csv" not in line
    assert "the output folder of python -m dem biaxial" in line
    assert _dem(["domain", "--biaxial", str(hmodel_folder), "--out", str(out)]) == 2
    assert "the output folder of python -m hmodel biaxial: allowed the output folder of " \
           "python -m dem biaxial" in _one_line(capsys)
    assert not out.exists()


def test_fit_data_that_is_no_curve(summary_json, tmp_path, capsys):
    out = tmp_path / "fit"
    assert _hmodel(["fit", "--data", str(summary_json), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "no column eps1, q" in line and "a CSV file with a header row naming eps1 and q" in line
    assert not out.exists()


def test_params_that_is_a_folder(tmp_path, capsys):
    assert _dem(["params", "--params", str(tmp_path), "--out", str(tmp_path / "p.json")]) == 2
    assert "is a folder: allowed a parameter file" in _one_line(capsys)


# -- what an interrupted run says it wrote -------------------------------------------------------
def test_stage_names_the_files_written_since_the_start(tmp_path):
    (tmp_path / "old.csv").write_text("a\n")
    st = Stage(str(tmp_path))
    assert st.line("SIGTERM").endswith("no output written yet")
    st.before = snapshot(tmp_path)
    (tmp_path / "biaxial.csv").write_text("eps1\n")
    (tmp_path / "states").mkdir()
    (tmp_path / "states" / "state_f0.900.npz").write_bytes(b"x")
    line = st.line("SIGTERM")
    assert line.endswith(f"written so far in {tmp_path}: biaxial.csv, "
                         f"{os.path.join('states', 'state_f0.900.npz')}"), line
    assert "old.csv" not in line


# -- progress lines ----------------------------------------------------------------------------
def test_material_point_progress_is_plain_lines_off_a_terminal():
    from hmodel.driver import _Progress
    s = io.StringIO()
    bar = _Progress(200, "drained path", stream=s)
    bar.PLAIN_MIN_S = 0.0
    for k in range(1, 201):
        bar.update(k)
    bar.close()
    lines = s.getvalue().splitlines()
    assert "\r" not in s.getvalue() and len(lines) == 10
    assert lines[0].startswith("drained path: 20/200 steps (10 %)")
    assert lines[-1].startswith("drained path: 200/200 steps (100 %)")

    class Tty(io.StringIO):
        def isatty(self):
            return True
    t = Tty()
    bar = _Progress(200, "drained path", stream=t)
    for k in range(1, 201):
        bar.update(k)
    bar.close()
    assert t.getvalue().startswith("\rdrained path: [")


def test_fem_progress_labels_its_checks(tmp_path, capsys):
    assert _fem(["biaxial", "--nx", "2", "--ny", "4", "--eps1-max", "0.001", "--d-eps1", "5e-4",
                 "--n-dir", "16", "--n-sphere", "20", "--no-fields",
                 "--out", str(tmp_path / "f")]) == 0
    steps = [s for s in capsys.readouterr().err.splitlines() if s.startswith("step")]
    assert steps and all("sign det K (platen displ./force) = +1/+1" in s and
                         "lam_min(K_s) (displ./force) = " in s and s.split("lam_min")[1]
                         .split("W2")[0].strip().endswith("Pa") for s in steps), steps
    assert "detK" not in "".join(steps) and "lam(Ks)" not in "".join(steps)
