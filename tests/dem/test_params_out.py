"""`dem params --out FILE`: --out names the file to write, so a second run replaces it (it was
refused as "an existing file, not a folder", the rule of the commands whose --out is a folder),
and a folder there is one line, exit 2."""
from dem.params import DemParams, load_params


def _main(argv, capsys):
    from dem.__main__ import main
    try:
        main(argv)
    except SystemExit as e:
        return e.code, capsys.readouterr().err.strip().splitlines()
    return 0, capsys.readouterr().err.strip().splitlines()


def test_params_rewrites_its_file(tmp_path, capsys):
    f = tmp_path / "p.json"
    assert _main(["params", "--out", str(f)], capsys)[0] == 0
    assert _main(["params", "--phi-g", "30", "--out", str(f)], capsys)[0] == 0
    assert load_params(f) == DemParams(phi_g=30.0)


def test_params_refuses_a_folder(tmp_path, capsys):
    code, err = _main(["params", "--out", str(tmp_path)], capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("error: --out") and "folder" in err[0]
    assert list(tmp_path.iterdir()) == []
