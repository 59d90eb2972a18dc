"""Outputs: the load curve CSV (row by row, flushed), the XDMF time series (XML rewritten
atomically after every step, heavy data in HDF5, flushed), the figure (atomic), helpers.

A run that fails part-way leaves every converged step on disk, complete and readable: the CSV
holds whole rows only (one write + flush per row), and fields.xdmf always describes exactly the
steps already flushed to fields.h5.
"""
from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from hmodel.io import atomic_write_bytes

__all__ = ["CurveWriter", "FieldWriter", "CURVE_COLUMNS", "plot_curve",
           "read_curve"]

CURVE_COLUMNS = [
    "step", "eps1", "s1", "s2", "q", "p", "eta",
    "det_k_sign", "lam_min_ks", "n_neg_ks", "log10_abs_det_k",
    "det_k_sign_f", "lam_min_ks_f", "n_neg_ks_f", "log10_abs_det_k_f",
    "w2_global", "w2_ext", "w2_global_raw", "w2_ext_raw",
    "newton_iters", "cutbacks", "d_eps1", "final_residual",
    "min_det_D", "min_det_Ds", "min_lam_Ds", "min_w2_local", "min_rice",
    "n_pts_w2_neg", "n_pts_rice_neg", "sliding_fraction", "open_fraction", "eps2_mean", "time_s",
]


class CurveWriter:
    """curve.csv, one row per converged step, written and flushed as the step converges."""

    def __init__(self, path, columns=CURVE_COLUMNS):
        self.path = Path(path)
        self.columns = list(columns)
        self._f = open(self.path, "w", newline="")
        self._f.write(",".join(self.columns) + "\n")
        self._f.flush()

    def write(self, row: dict) -> None:
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow([_fmt(row.get(c, "")) for c in self.columns])
        self._f.write(buf.getvalue())       # one write of a whole line
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self):
        if not self._f.closed:
            self._f.close()


def _fmt(v):
    if isinstance(v, (bool, np.bool_)):
        return int(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return v


def read_curve(path) -> dict:
    """curve.csv -> dict of column name -> float array."""
    data = np.genfromtxt(path, delimiter=",", names=True, dtype=float)
    data = np.atleast_1d(data)
    return {n: np.asarray(data[n]) for n in data.dtype.names}


def _writer_class():
    from meshio.xdmf.time_series import TimeSeriesWriter
    from meshio._common import ET

    class _Writer(TimeSeriesWriter):
        """meshio's TimeSeriesWriter with the HDF5 file beside the XDMF file (meshio 5.3 puts it
        in the current directory) and an atomic XML rewrite after each step, so the pair is
        readable at any time, not only after __exit__."""

        def __enter__(self):
            import h5py
            self.h5_filename = str(self.filename.with_suffix(".h5"))
            self.h5_file = h5py.File(self.h5_filename, "w")
            self._chunks = []
            return self

        def write_data(self, t, point_data=None, cell_data=None):
            super().write_data(t, point_data=point_data, cell_data=cell_data)
            # serialize each step's Grid once: the flush below then costs O(1) serialization per
            # step instead of re-serializing the whole growing tree
            chunk = ET.tostring(self.collection[-1])
            # the usual xi prefix for the XInclude namespace (ElementTree names it ns0)
            chunk = chunk.replace(b"xmlns:ns0=", b"xmlns:xi=").replace(b"<ns0:include", b"<xi:include")
            self._chunks.append(chunk)

        def flush(self):
            """Make fields.h5 durable and rewrite fields.xdmf atomically (same XML as meshio's
            __exit__ would write: Domain = temporal collection + the mesh grid)."""
            self.h5_file.flush()
            if not hasattr(self, "_chunks"):
                self._chunks = []
            coll = self.collection
            head = (b'<Xdmf Version="3.0"><Domain><Grid Name="%s" GridType="Collection" '
                    b'CollectionType="Temporal">' % coll.get("Name").encode())
            mesh = b"".join(ET.tostring(g) for g in self.domain if g is not coll)
            data = head + b"".join(self._chunks) + b"</Grid>" + mesh + b"</Domain></Xdmf>"
            atomic_write_bytes(self.filename, data)

        def __exit__(self, *_):
            self.flush()
            self.h5_file.close()

    return _Writer


class FieldWriter:
    """fields.xdmf + fields.h5: the mesh once, then point and cell data at every step."""

    def __init__(self, path, points: np.ndarray, cells: list):
        self._w = _writer_class()(Path(path))
        self._w.__enter__()
        self._w.write_points_cells(points, cells)
        self._w.flush()

    def write(self, t: float, point_data: dict, cell_data: dict) -> None:
        self._w.write_data(t, point_data=point_data, cell_data=cell_data)
        self._w.flush()

    def close(self):
        if self._w is not None:
            self._w.__exit__()
            self._w = None


def plot_curve(path, curve: dict, mp: dict | None = None, title: str = "") -> None:
    """q against eps1 (compression positive) with the first lam_min(K_s) <= 0 and the first
    det K sign change marked (both platen controls), beside the material-point curve."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    if mp is not None:
        ax.plot(100 * mp["eps1"], mp["q"] / 1e3, "k--", lw=1.2, zorder=3,
                label="material point (hmodel.driver, d_eps1 = 1e-5)")
    e, q = 100 * curve["eps1"], curve["q"] / 1e3
    ax.plot(e, q, "o-", ms=2.5, lw=1, color="C0", label="FE specimen")
    marks = first_events(curve)
    style = {"lam_min_ks": ("v", "C1", "first lam_min(K_s) <= 0 (platen displ.)"),
             "det_k": ("s", "C3", "first det K sign change (platen displ.)"),
             "lam_min_ks_f": ("^", "C2", "first lam_min(K_s) <= 0 (platen force)"),
             "det_k_f": ("D", "C4", "first det K sign change (platen force)")}
    for key, (m, c, lab) in style.items():
        k = marks.get(key)
        if k is not None:
            ax.plot(e[k], q[k], m, color=c, ms=9, mfc="none", mew=2, label=f"{lab}: eps1 = {e[k]:.3f} %")
    ax.set_xlabel("axial strain eps1 [%] (compression +)")
    ax.set_ylabel("q = s1 - s2 [kPa]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    if title:
        ax.set_title(title, fontsize=9)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def first_events(curve: dict) -> dict:
    """Row indices of the first lam_min_ks <= 0 and first det K sign change (vs row 0), for both
    platen controls; a key is absent when the event does not happen."""
    out = {}
    for suf in ("", "_f"):
        lam = curve["lam_min_ks" + suf]
        k = np.flatnonzero(lam <= 0)
        if k.size:
            out["lam_min_ks" + suf] = int(k[0])
        s = curve["det_k_sign" + suf]
        k = np.flatnonzero(s != s[0])
        if k.size:
            out["det_k" + suf] = int(k[0])
    return out
