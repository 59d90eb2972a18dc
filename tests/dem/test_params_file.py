"""Parameter files: `dem params` writes the full DemParams with units (the format shared with the
H-model, common.paramfile), every dem command reads one, options override it and the run says so,
the output folders record their parameters in the same format, files of the format before units
still load, and a state refuses parameters that are not its own."""
import json
from pathlib import Path

import pytest

from dem.params import UNITS, DemParams, load_params
from tests._cli import run_dem as _run


def test_params_file_round_trip_and_options_on_top(tmp_path, capsys):
    from dem.__main__ import main
    f = tmp_path / "p.json"
    main(["params", "--out", str(f)])
    d = json.loads(f.read_text())
    assert d.pop("model") == "dem" and d.pop("units") == UNITS
    assert d.pop("note") == "python -m dem params; parameters: the paper's set (defaults)"
    assert d == DemParams().to_dict()                 # the paper's stated set, every field
    g = tmp_path / "q.json"
    capsys.readouterr()
    main(["params", "--params", str(f), "--phi-g", "30", "--kn-over-d", "1e9", "--n", "500",
          "--out", str(g)])
    assert load_params(g) == DemParams(phi_g=30.0, kn_over_d=1e9, n=500)
    out = capsys.readouterr().out
    assert "--phi-g 30 overrides the file's phi_g 35" in out and "--n 500" in out
    main(["params", "--out", str(f)])                 # an existing file is replaced


def test_files_of_the_format_before_units_still_load(tmp_path):
    old = tmp_path / "old.json"
    old.write_text(json.dumps(DemParams(n=500).to_dict(), indent=1))   # the old `dem params`
    assert load_params(old) == DemParams(n=500)
    gallery = (Path(__file__).parents[2] / "docs" / "gallery" / "calibration" / "before_issue27"
               / "calibrated.json")
    assert load_params(gallery) == DemParams(n=2000, kn_over_d=8.723e9, phi_g=15.0,
                                             rolling_friction=0.2)   # written before units


def test_files_with_the_friction_key_before_phi_g_still_load(tmp_path, capsys):
    """DemParams.friction_deg became phi_g (issue 32, one name with the H-model and the option
    --phi-g): a parameter file, a state and a run's summary of before load under the new key."""
    from dem import io
    from dem.params import migrate
    d = DemParams(n=300, phi_g=25.0).to_dict()
    old = {("friction_deg" if k == "phi_g" else k): v for k, v in d.items()}
    units = {("friction_deg" if k == "phi_g" else k): v for k, v in UNITS.items()}
    f = tmp_path / "old_units.json"
    f.write_text(json.dumps({"model": "dem", **old, "units": units, "note": "python -m dem params"}))
    assert load_params(f) == DemParams(n=300, phi_g=25.0)
    (tmp_path / "old_plain.json").write_text(json.dumps(old))
    assert load_params(tmp_path / "old_plain.json") == DemParams(n=300, phi_g=25.0)
    assert DemParams.from_dict(old) == DemParams(n=300, phi_g=25.0)     # states, summaries
    for gallery in ("calibration/before_issue34/params.json",):   # written before the renaming
        text = (Path(__file__).parents[2] / "docs" / "gallery" / gallery).read_text()
        assert '"friction_deg"' in text
        assert load_params(Path(__file__).parents[2] / "docs" / "gallery" / gallery).phi_g > 0
    both = {**old, "phi_g": 30.0}           # both keys: not silently one of them
    (tmp_path / "both.json").write_text(json.dumps(both))
    with pytest.raises(ValueError, match="unknown key 'friction_deg'"):
        load_params(tmp_path / "both.json")
    assert migrate(both) == both
    from dem.__main__ import main
    main(["params", "--params", str(f), "--out", str(tmp_path / "new.json")])
    new = json.loads((tmp_path / "new.json").read_text())
    assert new["phi_g"] == 25.0 and "friction_deg" not in new and new["units"]["phi_g"] == "deg"


BIAXIAL = ["biaxial", "--n", "100", "--seed", "3", "--rate", "0.5", "--eps1-max", "0.004",
           "--no-vtk", "--save-fractions", "1", "--threads", "1"]


def _biaxial_rows(out, capsys, *extra):
    from dem.__main__ import main
    main([*BIAXIAL, "--out", str(out), *extra])
    capsys.readouterr()
    return (out / "biaxial.csv").read_bytes()


def test_file_run_equals_the_default_run_and_repeats_from_its_folder(tmp_path, capsys):
    """`dem params --out p.json && dem biaxial --params p.json` is the default run to the bit;
    a hand-edited file changes it; the folder's params.json repeats it."""
    from dem.__main__ import main
    p = tmp_path / "p.json"
    main(["params", "--out", str(p)])
    default = _biaxial_rows(tmp_path / "a", capsys)
    assert _biaxial_rows(tmp_path / "b", capsys, "--params", str(p)) == default
    assert load_params(tmp_path / "a" / "params.json") == DemParams(n=100, seed=3)
    assert _biaxial_rows(tmp_path / "c", capsys, "--params",
                         str(tmp_path / "a" / "params.json")) == default
    d = json.loads(p.read_text())
    d["phi_g"] = 25
    p.write_text(json.dumps(d))
    assert _biaxial_rows(tmp_path / "d", capsys, "--params", str(p)) != default
    rec = json.loads((tmp_path / "d" / "params.json").read_text())
    assert rec["phi_g"] == 25.0 and "--n 100 overrides the file's n 12000" in rec["note"]


def test_bad_params_files_are_one_line_errors(tmp_path, capsys):
    d = DemParams().to_dict()
    cases = {"typo.json": ({**d, "kn_typo": 1.0}, "'kn_typo'"),
             "missing.json": ({k: v for k, v in d.items() if k != "seed"}, "'seed'"),
             "range.json": ({**d, "phi_g": 95.0}, "phi_g"),
             "type.json": ({**d, "n": "12000"}, "n = \"12000\""),
             "float_n.json": ({**d, "n": 12000.0}, "allowed an integer"),
             "unit.json": ({**d, "units": {"density": "g/cm^3"}}, "units.density"),
             "hmodel.json": ({**d, "model": "hmodel"}, "model")}
    for name, (content, _) in cases.items():
        (tmp_path / name).write_text(json.dumps(content))
    (tmp_path / "junk.json").write_text("{not json")
    needles = {**{k: v[1] for k, v in cases.items()}, "junk.json": "not JSON",
               "absent.json": "no such file"}
    for name, needle in needles.items():
        for cmd in (["biaxial", "--params"], ["calibrate", "--params"], ["crosscheck", "--dem-params"]):
            code, err = _run([*cmd, str(tmp_path / name), "--out", str(tmp_path / "o")], capsys)
            assert code == 2 and len(err) == 1 and cmd[-1] in err[0] and name in err[0], err
            assert needle in err[0], (needle, err)
    assert not (tmp_path / "o").exists()


def test_a_state_refuses_parameters_that_are_not_its_own(small_sample, tmp_path, capsys):
    from dem import io
    from dem.params import save_params
    io.save_state(tmp_path / "s.npz", small_sample)
    own = tmp_path / "own.json"
    save_params(own, small_sample.params)
    other = tmp_path / "other.json"
    save_params(other, small_sample.params.replace(phi_g=20.0))
    code, err = _run(["probes", "--state", str(tmp_path / "s.npz"), "--params", str(other),
                      "--out", str(tmp_path / "p")], capsys)
    assert code == 2 and len(err) == 1 and "phi_g" in err[0], err
    assert not (tmp_path / "p").exists()
    from dem.__main__ import _check_state_params
    import argparse
    _check_state_params(small_sample.params, argparse.Namespace(params=str(own), damping=None))


def test_crosscheck_takes_an_hmodel_file(tmp_path, capsys):
    """`crosscheck --hmodel-params FILE`: the H-model part runs the file's material at the
    cross-check's 200 kPa; a file of the other model is refused before anything runs."""
    from crosscheck import hmodel_part
    from dem.params import save_params
    from hmodel import HParams
    h = hmodel_part(domain_sigma2=(), params=HParams(n_dir=36, phi_g=25.0, p0=1e5))
    assert h["params"] == HParams(n_dir=36, phi_g=25.0, p0=200e3)
    f = tmp_path / "dem.json"
    save_params(f, DemParams())
    capsys.readouterr()      # what hmodel_part printed (a compile notice, if a kernel compiled)
    code, err = _run(["crosscheck", "--hmodel-params", str(f), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and len(err) == 1 and "--hmodel-params" in err[0], err
    assert 'model = "dem": allowed "hmodel"' in err[0]
    assert not (tmp_path / "o").exists()


def test_fingerprints_are_those_of_before_phi_g():
    """A state's fingerprint (what --resume of probes, domain and burst checks) hashes the
    parameters under their keys of before the renaming (friction_deg): a sweep started before
    it resumes. The hash below is the one the code before issue 32 gives this state."""
    from dem.probes import state_fingerprint
    from dem.sample import generate
    from dem.simulation import Simulation
    p = DemParams(n=50, seed=3)
    x, r, walls = generate(p)
    assert state_fingerprint(Simulation.new(p, x, r, walls).state()) == \
        "e53561b30c195531309818126af0880d18de2ac34be3f74e1d8399866fc34ec0"
