"""The DEM's and the cross-check's polar W2 figures show their cones (issue 26): the probed
directions that failed or settled with W2 <= 0 shaded and labelled with their angles, the
plastic zone at the rim, angle ticks, a zoom where the cone is narrow. Drawn from the 12,000-disk
run's probes (docs/gallery/full/probes.csv: one failure, at 160 deg) and a coarse H-model sweep."""
from pathlib import Path

import numpy as np
import pytest

from dem import io

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def figures(monkeypatch):
    import matplotlib.pyplot as plt
    got = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (got.append(fig), close(fig)))
    return got


@pytest.fixture(scope="module")
def gallery_rows():
    return io.read_csv(ROOT / "docs" / "gallery" / "full" / "probes.csv")[1]


def _texts(fig):
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def test_fig15_marks_the_failed_direction(gallery_rows, figures, tmp_path):
    from dem.probes import plot_probes
    plot_probes(gallery_rows, tmp_path, note="state_f0.950, 12000 disks")
    fig15 = figures[0]
    polar = fig15.axes[0]
    assert polar.name == "polar" and len(fig15.axes) == 2          # a narrow cone: the zoom
    assert any("160.0°" in t for t in _texts(fig15))
    labels = [t.get_text() for t in fig15.legends[0].get_texts()]
    assert any(s.startswith("plastic zone") and "70.0°-150.0°" in s for s in labels)
    assert "30°" in [t.get_text() for t in polar.get_xticklabels()]
    assert (tmp_path / "fig15_w2.png").stat().st_size > 10_000


def test_crosscheck_polar_figure(gallery_rows, figures, tmp_path):
    from crosscheck.figures import polar_figure
    from hmodel import HParams
    from hmodel.experiment import state_at_eta
    from hmodel.probes import arcs, directional_sweep
    P = HParams(n_dir=36)
    _, sA = state_at_eta(P, 1.029, d_eps1=1e-4)
    sw = directional_sweep(sA, P, n=120)
    cone = arcs(sw.alpha_sigma, sw.w2 <= 0)
    assert cone and sum(b - a for a, b in cone) < 30          # narrow at A, as with 180
    polar_figure(tmp_path / "p.png", {"sweep": sw}, gallery_rows, "DEM")
    (fig,) = figures
    assert [ax.name for ax in fig.axes] == ["polar", "polar", "rectilinear"]
    texts = _texts(fig)
    assert any(f"{cone[0][0]:.1f}°-{cone[0][1]:.1f}°" in t for t in texts)     # the H-model's
    assert any("160.0°" in t for t in texts)                                    # the DEM's
    zoom = fig.axes[2]
    x0, x1 = zoom.get_xlim()
    assert x0 < cone[0][0] and x1 > cone[-1][1]
    assert np.isfinite(x0) and (tmp_path / "p.png").stat().st_size > 10_000
