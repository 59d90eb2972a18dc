"""What `dem biaxial` prints (issue 26): numbers formatted to their precision, no raw floats
(`porosity after compaction=0.17286062490718235`) and no numpy arrays (`stress=[188853.1 ...]`)."""
import re

BIAXIAL = ["biaxial", "--n", "100", "--seed", "3", "--rate", "0.5", "--eps1-max", "0.004",
           "--no-vtk", "--save-fractions", "1", "--threads", "1"]


def test_biaxial_lines_are_formatted(tmp_path, capsys):
    from dem.__main__ import main
    main([*BIAXIAL, "--out", str(tmp_path / "b")])
    cap = capsys.readouterr()
    text = cap.out + cap.err
    assert not re.search(r"\d\.\d{7,}", text), text          # no float printed in full
    assert not re.search(r"=\s*\[\s*\d", text), text         # no numpy array
    last = cap.out.strip().splitlines()[-1]
    assert re.search(r"porosity after compaction 0\.\d{4};", last), last
    assert re.search(r"\(eta 1\.029 (reached|not reached)", last), last
    assert re.search(r"\[compact\] porosity=0\.\d{4} stress=\(\d+\.\d, \d+\.\d\) kPa", cap.err)


def test_bench_prints_rounded_figures(monkeypatch, capsys):
    import dem.bench
    from dem.__main__ import main
    monkeypatch.setattr(dem.bench, "bench", lambda **k: {
        "n": 100, "busy_core": False, "particle_steps_per_s_auto": 12345678.91234,
        "ratio_auto_to_1_thread": 0.987654321, "ledger_cost": 1.0612345})
    main(["bench", "--n", "100", "--steps", "1"])          # exit 0: returns
    out = capsys.readouterr().out
    assert "particle_steps_per_s_auto: 1.235e+07" in out and "ratio_auto_to_1_thread: 0.9877" in out
    assert "ledger_cost: 1.061 (a step's time with the energy ledger over without it)" in out
    assert "n: 100" in out and "busy_core: False" in out
