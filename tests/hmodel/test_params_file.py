"""Parameter files of the H-model (docs/parameters.md, issue 19 part 1): ``python -m hmodel params
--out FILE`` writes Table I with units, ``--params FILE`` gives the same run as the defaults to the
bit, a hand-edited file changes it, an option given overrides the file and the run says so, every
output folder records its parameters in the same format (so the run repeats from them), and a bad
file is one line naming the key, exit 2, before anything is computed or written."""
import json

import pytest

import hmodel.cli as cli
import point.cli
from hmodel import HParams
from hmodel.params import UNITS, load_params, save_params

SMALL = ["--eps1-max", "0.004", "--d-eps1", "1e-4", "--quiet"]     # 40 steps, 180 orientations


def _biaxial(out, *extra):
    assert cli.main(["biaxial", *SMALL, "--out", str(out), *extra]) == 0
    return (out / "biaxial.csv").read_bytes()


@pytest.fixture
def table_one(tmp_path):
    f = tmp_path / "p.json"
    assert cli.main(["params", "--out", str(f)]) == 0
    return f


def test_params_writes_table_one_with_units(table_one):
    d = json.loads(table_one.read_text())
    assert d.pop("model") == "hmodel" and d.pop("units") == UNITS
    assert d.pop("note") == "python -m hmodel params; parameters: Table I (defaults)"
    P = HParams()
    assert d == {k: getattr(P, k) for k in UNITS}            # every field, Table I
    assert list(d) == list(UNITS) and load_params(table_one) == P


def test_file_run_equals_the_default_run_to_the_bit_and_repeats_from_its_folder(tmp_path, table_one,
                                                                                capsys):
    default = _biaxial(tmp_path / "a")
    assert _biaxial(tmp_path / "b", "--params", str(table_one)) == default
    out = capsys.readouterr().out
    assert "parameters: Table I (defaults)" in out and f"parameters: the file {table_one}" in out
    # the folder records what it ran with, in the same format: it repeats the run
    assert load_params(tmp_path / "a" / "params.json") == HParams()
    assert _biaxial(tmp_path / "c", "--params", str(tmp_path / "a" / "params.json")) == default


def test_a_hand_edited_file_changes_the_run(tmp_path, table_one):
    d = json.loads(table_one.read_text())
    d["phi_g"] = 25                       # an integer where a number is due: accepted
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(d))
    default = _biaxial(tmp_path / "a")
    changed = _biaxial(tmp_path / "b", "--params", str(edited))
    assert changed != default
    assert changed == _biaxial(tmp_path / "c", "--phi-g", "25")
    assert load_params(tmp_path / "b" / "params.json") == HParams(phi_g=25.0)


def test_options_override_the_file_and_the_run_says_so(tmp_path, table_one, capsys):
    capsys.readouterr()
    run = _biaxial(tmp_path / "a", "--params", str(table_one), "--phi-g", "25", "--sigma2", "1e5")
    out = capsys.readouterr().out
    assert "--phi-g 25 overrides the file's phi_g 20" in out
    assert "--sigma2 100000 overrides the file's p0 200000" in out
    rec = json.loads((tmp_path / "a" / "params.json").read_text())
    assert rec["phi_g"] == 25.0 and rec["p0"] == 100e3 and "--phi-g 25 overrides" in rec["note"]
    # the recorded p0 is the confining stress of the run: --params alone repeats it
    assert _biaxial(tmp_path / "b", "--params", str(tmp_path / "a" / "params.json")) == run
    # without a file an option is reported against the default
    _biaxial(tmp_path / "c", "--kn", "2e6")
    assert "--kn 2e+06 (default 1e+06)" in capsys.readouterr().out


def test_domain_pressures_follow_p0(tmp_path, monkeypatch, capsys):
    """The domain's default pressures are p0/2, p0, 2 p0 (Table I: the paper's 100, 200, 400
    kPa, exactly); --sigma2 replaces them."""
    seen = []

    def stop(P, pressures, **kw):
        seen.append(list(pressures))
        raise KeyboardInterrupt

    monkeypatch.setattr(point.cli, "bifurcation_domain", stop)     # python -m hmodel's commands
    monkeypatch.setattr(point.cli, "compile_kernels", lambda **kw: 0.0)
    f = tmp_path / "p.json"
    save_params(f, HParams(p0=50e3))
    for argv in ([], ["--params", str(f)], ["--params", str(f), "--sigma2", "1e5,3e5"]):
        assert cli.main(["domain", *argv, "--out", str(tmp_path / "d")]) == 130
    assert seen == [[100e3, 200e3, 400e3], [25e3, 50e3, 100e3], [1e5, 3e5]]


def _edit(d, **kw):
    d = dict(d)
    for k, v in kw.items():
        if v is _DROP:
            d.pop(k)
        else:
            d[k] = v
    return json.dumps(d)


_DROP = object()
GOOD = {"model": "hmodel", **{k: getattr(HParams(), k) for k in UNITS}, "units": UNITS}
BAD_FILES = {
    "unknown key": (_edit(GOOD, kn_typo=1.0), "'kn_typo'"),
    "missing key": (_edit(GOOD, alpha0=_DROP), "'alpha0'"),
    "a string": (_edit(GOOD, kn="1e6"), "kn = \"1e6\""),
    "a bool": (_edit(GOOD, r_g=True), "r_g = true"),
    "null where not allowed": (_edit(GOOD, kt=None), "kt = null"),
    "not an integer": (_edit(GOOD, n_dir=180.5), "n_dir = 180.5"),
    "NaN": (_edit(GOOD, phi_g=float("nan")), "phi_g = NaN"),
    "out of range": (_edit(GOOD, phi_g=95), "phi_g = 95.0 is out of range: allowed 0 < phi_g < 90"),
    "too few orientations": (_edit(GOOD, n_dir=4), "n_dir = 4 is out of range"),
    "another unit": (_edit(GOOD, units={**UNITS, "kn": "kN/m"}), "units.kn = \"kN/m\""),
    "a DEM file": (_edit(GOOD, model="dem"), "model = \"dem\""),
    "twice the same key": (json.dumps(GOOD)[:-1] + ', "kn": 2e6}', "'kn' is given twice"),
    "not JSON": ("{kn: 1e6", "not JSON"),
    "not an object": ("[1, 2]", "a JSON object"),
}


@pytest.mark.parametrize("cmd", ["biaxial", "probes", "domain", "params"])
@pytest.mark.parametrize("case", list(BAD_FILES) + ["missing file"])
def test_bad_file_is_one_line_naming_the_key(tmp_path, capsys, no_computation, cmd, case):
    f = tmp_path / "bad.json"
    if case != "missing file":
        f.write_text(BAD_FILES[case][0])
    needle = BAD_FILES[case][1] if case != "missing file" else "no such file"
    out = tmp_path / ("o.json" if cmd == "params" else "out")
    assert cli.main([cmd, "--params", str(f), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: --params {f}: ") and "\n" not in err, err
    assert needle in err and "Traceback" not in err, (needle, err)
    assert not out.exists()


def test_params_out_must_be_a_file_in_a_writable_folder(tmp_path, capsys):
    assert cli.main(["params", "--out", str(tmp_path)]) == 2
    assert "--out" in capsys.readouterr().err
    assert cli.main(["params", "--out", str(tmp_path / "no" / "p.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
    f = tmp_path / "p.json"
    for _ in range(2):                               # an existing file is replaced
        assert cli.main(["params", "--n-dir", "36", "--out", str(f)]) == 0
    assert load_params(f) == HParams(n_dir=36)
