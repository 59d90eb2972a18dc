"""The CLI writes what it promises (small runs: coarse fabric, short paths)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from hmodel.cli import main
from common.io import read_csv


def test_biaxial_cli(tmp_path, capsys):
    out = tmp_path / "b"
    assert main(["biaxial", "--eps1-max", "0.03", "--d-eps1", "1e-4", "--n-dir", "36", "--out", str(out), "--quiet"]) == 0
    c = read_csv(out / "biaxial.csv")
    for k in ("eps1", "eps2", "eps_v", "s1", "s2", "p", "q", "eta"):
        assert k in c
    assert np.allclose(c["p"], 0.5 * (c["s1"] + c["s2"])) and np.allclose(c["q"], c["s1"] - c["s2"])
    assert np.allclose(c["eps_v"], c["eps1"] + c["eps2"])
    assert np.allclose(c["s2"], 200e3) and c["eps1"][-1] == pytest.approx(0.03)
    for f in ("fig4_q_eps1.png", "fig5_epsv_eps1.png"):
        assert (out / f).stat().st_size > 10_000
    assert "peak" in capsys.readouterr().out
    assert not [f for f in os.listdir(out) if f.endswith(".tmp")]


def test_probes_cli(tmp_path):
    out = tmp_path / "p"
    assert main(["probes", "--n-dir", "36", "--n-probes", "72", "--d-eps1", "1e-4", "--stress-step", "30",
                 "--out", str(out)]) == 0
    c = read_csv(out / "probes.csv")
    for k in ("alpha_eps", "alpha_sigma", "w2", "w2_sigma", "w2_V", "w2_g", "w2_micro", "w2n", "w2t", "plastic"):
        assert k in c
    assert np.all((c["alpha_sigma"] >= 0) & (c["alpha_sigma"] < 360))
    assert np.allclose(c["w2"], c["w2_sigma"] + c["w2_V"] + c["w2_g"], atol=1e-12)
    s = json.loads((out / "summary.json").read_text())
    assert s["eta_A"] >= 1.029 and s["plastic_zone_alpha_sigma"]
    for f in ("fig3_probes.png", "fig6_axial_components.png", "fig7_lateral_components.png",
              "fig8_polar_w2.png", "fig9_w2_split.png", "fig11_w2_normal_tangential.png"):
        assert (out / f).stat().st_size > 10_000


def test_domain_cli(tmp_path):
    out = tmp_path / "d"
    assert main(["domain", "--sigma2", "100e3,300e3", "--n-dir", "36", "--n-probes", "72", "--d-eps1", "1e-4",
                 "--workers", "2", "--out", str(out)]) == 0
    c = read_csv(out / "domain.csv")
    assert list(c["sigma2"]) == [100e3, 300e3]
    # lower boundary below the peak; W2_sigma fires no later than W2 (Fig. 10)
    assert np.all(c["q_w2"] <= c["q_peak"]) and np.all(c["q_w2sigma"] <= c["q_w2"] + 1e-6)
    assert (out / "fig10_domain.png").stat().st_size > 10_000


def test_bad_parameter_is_a_clear_error(tmp_path, capsys):
    assert main(["biaxial", "--phi-g", "95", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "phi_g" in err and "0 < phi_g < 90" in err
    assert not (tmp_path / "x").exists()


def test_module_entry_point(tmp_path):
    r = subprocess.run([sys.executable, "-m", "hmodel", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "biaxial" in r.stdout and "probes" in r.stdout and "domain" in r.stdout
