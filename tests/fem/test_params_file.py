"""python -m fem biaxial --params FILE (docs/parameters.md, issue 19 part 1): a file written by
``python -m hmodel params`` gives the default run to the bit, a hand-edited one changes it, an
option overrides the file and the run says so, the output folder records the material in the
same format (the run repeats from it), a bad file is one line naming the key, exit 2, nothing
written."""
import csv
import json

import pytest

import fem.__main__ as fcli
import hmodel.cli as hcli
from hmodel import HParams
from hmodel.params import load_params

# 2 x 4 quads (32 points, 180 orientations), two steps to eps1 = 0.1 %
SMALL = ["--nx", "2", "--ny", "4", "--eps1-max", "0.001", "--d-eps1", "5e-4", "--n-sphere", "50",
         "--no-fields", "--quiet"]


def _curve(out, *extra):
    """The run's curve.csv without its timing column (time_s)."""
    assert fcli.main(["biaxial", *SMALL, "--out", str(out), *extra]) == 0
    with open(out / "curve.csv") as f:
        rows = list(csv.reader(f))
    k = rows[0].index("time_s")
    return [r[:k] + r[k + 1:] for r in rows]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("fem_params")
    p = d / "p.json"
    assert hcli.main(["params", "--out", str(p)]) == 0
    edited = json.loads(p.read_text())
    edited["phi_g"] = 25.0
    (d / "edited.json").write_text(json.dumps(edited))
    return d, {"default": _curve(d / "default"), "file": _curve(d / "file", "--params", str(p)),
               "edited": _curve(d / "edited", "--params", str(d / "edited.json")),
               "option": _curve(d / "option", "--params", str(p), "--phi-g", "25")}


def test_file_run_equals_the_default_run_to_the_bit(runs):
    d, c = runs
    assert c["file"] == c["default"] and len(c["default"]) == 1 + 3      # header, rows 0-2
    assert load_params(d / "default" / "params.json") == HParams()
    assert json.loads((d / "file" / "summary.json").read_text())["parameters"] == \
        f"parameters: the file {d / 'p.json'}"


def test_a_hand_edited_file_changes_the_run_and_an_option_overrides_it(runs, capsys):
    d, c = runs
    assert c["edited"] != c["default"] and c["edited"] == c["option"]
    note = json.loads((d / "option" / "summary.json").read_text())["parameters"]
    assert "--phi-g 25 overrides the file's phi_g 20" in note
    assert load_params(d / "option" / "params.json") == HParams(phi_g=25.0)


def test_the_recorded_file_repeats_the_run(runs, tmp_path):
    d, c = runs
    assert _curve(tmp_path / "again", "--params", str(d / "option" / "params.json")) == c["option"]


@pytest.mark.parametrize("content,needle", [
    ('{"kn": 1e6}', "missing key 'kt'"),
    ("{nope", "not JSON"),
    (None, "no such file"),
])
def test_bad_file_is_one_line_nothing_written(tmp_path, capsys, no_computation, content, needle):
    f = tmp_path / "p.json"
    if content is not None:
        f.write_text(content)
    out = tmp_path / "out"
    assert fcli.main(["biaxial", "--params", str(f), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: --params {f}: ") and needle in err and "\n" not in err, err
    assert not out.exists()
