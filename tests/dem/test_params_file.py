"""Parameter files: `dem params` writes the full DemParams, every dem command reads one, options
override it, and a state refuses parameters that are not its own."""
import json

import pytest

from dem.params import DemParams


def _run(argv, capsys):
    from dem.__main__ import main
    with pytest.raises(SystemExit) as e:
        main(argv)
    return e.value.code, capsys.readouterr().err.strip().splitlines()


def test_params_file_round_trip_and_options_on_top(tmp_path, capsys):
    from dem.__main__ import main
    f = tmp_path / "p.json"
    main(["params", "--out", str(f)])
    d = json.loads(f.read_text())
    assert d == DemParams().to_dict()                 # the paper's stated set, every field
    g = tmp_path / "q.json"
    main(["params", "--params", str(f), "--friction", "30", "--kn-over-d", "1e9", "--n", "500",
          "--out", str(g)])
    assert DemParams.from_dict(json.loads(g.read_text())) == DemParams(
        friction_deg=30.0, kn_over_d=1e9, n=500)


def test_bad_params_files_are_one_line_errors(tmp_path, capsys):
    d = DemParams().to_dict()
    cases = {"typo.json": {**d, "kn_typo": 1.0}, "missing.json": {k: v for k, v in d.items()
                                                                  if k != "seed"},
             "range.json": {**d, "friction_deg": 95.0}}
    for name, content in cases.items():
        (tmp_path / name).write_text(json.dumps(content))
    (tmp_path / "junk.json").write_text("{not json")
    for name in list(cases) + ["junk.json", "absent.json"]:
        code, err = _run(["biaxial", "--params", str(tmp_path / name), "--out",
                          str(tmp_path / "o")], capsys)
        assert code == 2 and len(err) == 1 and "--params" in err[0] and name in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_state_refuses_parameters_that_are_not_its_own(small_sample, tmp_path, capsys):
    from dem import io
    io.save_state(tmp_path / "s.npz", small_sample)
    own = tmp_path / "own.json"
    own.write_text(json.dumps(small_sample.params.to_dict()))
    other = tmp_path / "other.json"
    other.write_text(json.dumps(small_sample.params.replace(friction_deg=20.0).to_dict()))
    code, err = _run(["probes", "--state", str(tmp_path / "s.npz"), "--params", str(other),
                      "--out", str(tmp_path / "p")], capsys)
    assert code == 2 and len(err) == 1 and "friction_deg" in err[0], err
    assert not (tmp_path / "p").exists()
    from dem.__main__ import _check_state_params
    import argparse
    _check_state_params(small_sample.params, argparse.Namespace(params=str(own), damping=None))
