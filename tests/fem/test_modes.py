"""Bifurcation modes as point fields of fields.xdmf (mode_ks, mode_ks_f, mode_detk, mode_detk_f),
read back with meshio, and where the first mode of the weak-band specimen lives.

The share of a mode inside the band is measured on the mode's strain, sum over the band's points of
|eps(mode)|^2 dx against the whole specimen's: a localized mode is a jump of displacement across
the band, so its displacement is not concentrated there (the blocks on either side move), its
strain is.
"""
import meshio
import numpy as np
import pytest

from fem.biaxial import BiaxialConfig, run_biaxial
from fem.output import MODE_FIELDS


@pytest.fixture(scope="module")
def band_run(tmp_path_factory):
    """``--imperfection band --imp-phi-g 15`` (default size 0.1 B, 45 deg), 8 x 16 quads, n_dir 36,
    from the isotropic state to eps1 = 1.25 %: lam_min(K_s) <= 0 first at 1.0 % (platen force) and
    1.2 % (platen displacement)."""
    out = tmp_path_factory.mktemp("band_modes")
    cfg = BiaxialConfig(nx=8, ny=16, n_dir=36, d_eps1=5e-4, eps1_max=0.0125, imperfection="band",
                        imp_phi_g=15.0, n_sphere=300, mp_reference=False)
    return run_biaxial(cfg, out)


def _modes(run):
    """name -> (rows, nnodes, 3) of every step, read back with meshio."""
    with meshio.xdmf.TimeSeriesReader(run.out_dir / "fields.xdmf") as r:
        r.read_points_cells()
        data = [r.read_data(k)[1] for k in range(r.num_steps)]
    return {name: np.stack([pd[name] for pd in data]) for name in MODE_FIELDS}


def _strain_share(prob, field, weak):
    nd = np.asarray(prob.basis.nodal_dofs)
    u = np.zeros(prob.ndofs)
    u[nd[0]], u[nd[1]] = field[:, 0], field[:, 1]
    e2 = np.sum(prob.strain(u).reshape(4, -1) ** 2, axis=0) * prob.dx.reshape(-1)
    e2 = e2.reshape(prob.nel, -1).sum(axis=1)
    return e2[weak].sum() / e2.sum()


def test_mode_fields_fire_with_the_criteria(band_run):
    """mode_ks[_f] is non-zero exactly at the rows where lam_min(K_s[_f]) <= 0, normalized to a
    largest nodal displacement of 1, zero on the prescribed dofs (bottom u_y, top u_y for the
    displacement-controlled platen; the top moves as one for the force-controlled platen);
    mode_detk[_f] only at the rows where det K[_f] changed sign (none before the peak)."""
    c, prob = band_run.curve, band_run.problem
    modes = _modes(band_run)
    p = prob.mesh.p
    bottom, top = np.isclose(p[1], p[1].min()), np.isclose(p[1], p[1].max())
    for suf in ("", "_f"):
        m = modes["mode_ks" + suf]
        fired = c["lam_min_ks" + suf] <= 0
        assert fired.any() and not fired.all()
        assert np.array_equal(np.any(m != 0, axis=(1, 2)), fired)
        norms = np.linalg.norm(m[fired], axis=2)
        assert np.allclose(norms.max(axis=1), 1.0, rtol=1e-12)
        assert np.all(m[:, :, 2] == 0) and np.all(m[:, bottom, 1] == 0)
        if suf == "":
            assert np.all(m[:, top, 1] == 0)
        else:
            assert np.allclose(m[:, top, 1], m[:, top, 1][:, :1], rtol=0, atol=1e-14)
        d = c["det_k_sign" + suf]
        changed = np.r_[False, d[1:] != d[:-1]]
        assert np.array_equal(np.any(modes["mode_detk" + suf] != 0, axis=(1, 2)), changed)
    for suf in ("", "_f"):
        png = (band_run.out_dir / f"mode_ks{suf}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_first_force_controlled_mode_concentrates_in_the_band(band_run):
    """At its first firing the mode of lam_min(K_s) with the platen force prescribed has 2.1 x the
    band's share of the area in its strain (measured 0.40 against 0.19 here; 0.44 against 0.15 on
    10 x 20 quads with n_dir 180). The displacement-controlled mode fires later and is not
    localized there: its strain sits near the platens (measured 0.05 of it in the band, a
    bending/barrelling mode), recorded, not asserted beyond being a different mode."""
    c, prob = band_run.curve, band_run.problem
    modes = _modes(band_run)
    weak = np.zeros(prob.nel, dtype=bool)
    weak[prob.weak_elements] = True
    area = prob.dx.sum(axis=1)
    area_share = area[weak].sum() / area.sum()
    k_f = int(np.flatnonzero(c["lam_min_ks_f"] <= 0)[0])
    k_d = int(np.flatnonzero(c["lam_min_ks"] <= 0)[0])
    share_f = _strain_share(prob, modes["mode_ks_f"][k_f], weak)
    share_d = _strain_share(prob, modes["mode_ks"][k_d], weak)
    print(f"band area share {area_share:.3f}; strain share of mode_ks_f at row {k_f}: {share_f:.3f}, "
          f"of mode_ks at row {k_d}: {share_d:.3f}")
    assert 0 < area_share < 0.5
    assert share_f > 1.5 * area_share
    assert k_f < k_d and share_d < share_f
