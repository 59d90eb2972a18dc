"""Outputs: the load curve CSV (row by row, flushed), the XDMF time series (heavy data in HDF5,
flushed every step; the XML rewritten atomically at most every ``FieldWriter.XML_EVERY`` seconds
and at the end), the figure (atomic), helpers.

A run that fails part-way leaves every converged step on disk, complete and readable: the CSV
holds whole rows only (one write + flush per row); fields.h5 is flushed after every step, and
fields.xdmf always describes steps already flushed to fields.h5. A run that ends by an exception,
Ctrl-C or SIGTERM closes the writer (run_biaxial's ``finally``), which rewrites the XML: then
fields.xdmf holds every converged step, like curve.csv. A process killed outright (SIGKILL, a
crash of the interpreter) leaves a readable pair too, whose XML lacks at most the steps of its
last XML_EVERY seconds (fields.h5 holds them; the next rewrite would have listed them). Flushed
to the operating system, not fsynced: that survives the process, not a power cut; an fsync per
step cost 3.5 ms here (up to 8 % of a 20 x 40 step's indicators and output).
"""
from __future__ import annotations

import csv
import io
import time
from pathlib import Path

import numpy as np

from common.io import atomic_write_bytes

__all__ = ["CurveWriter", "FieldWriter", "CURVE_COLUMNS", "MODE_FIELDS", "plot_curve", "read_curve",
           "nodal_vector", "mode_fields", "cell_tensor", "plot_mode"]

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
        self._f.flush()                     # to the OS: a process that dies leaves whole rows

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
        in the current directory) and an atomic XML rewrite on request (``flush``), so the pair
        is readable at any time, not only after __exit__."""

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

        def flush(self, xml: bool = True):
            """Push fields.h5 to the OS and, with ``xml``, rewrite fields.xdmf atomically (same
            XML as meshio's __exit__ would write: Domain = temporal collection + the mesh grid).
            The XML is replaced (``common.io.atomic_write_bytes``: a file written beside it), not
            fsynced: a process that dies leaves the pair complete (the kernel holds both), and an
            fsync of the XML alone would not make the HDF5 data it points to durable (it cost
            3.5 ms a step here)."""
            self.h5_file.flush()
            if not xml:
                return
            if not hasattr(self, "_chunks"):
                self._chunks = []
            coll = self.collection
            head = (b'<Xdmf Version="3.0"><Domain><Grid Name="%s" GridType="Collection" '
                    b'CollectionType="Temporal">' % coll.get("Name").encode())
            mesh = b"".join(ET.tostring(g) for g in self.domain if g is not coll)
            data = head + b"".join(self._chunks) + b"</Grid>" + mesh + b"</Domain></Xdmf>"
            atomic_write_bytes(self.filename, data, fsync=False)

        def __exit__(self, *_):
            self.flush()
            self.h5_file.close()

    return _Writer


class FieldWriter:
    """fields.xdmf + fields.h5: the mesh once, then point and cell data at every step. fields.h5
    is flushed after every step, the XML rewritten after a step when ``xml_every`` seconds
    (default XML_EVERY) have passed since its last rewrite, and always by ``close`` (see the
    module docstring for what an interrupted run leaves). The rewrite costs O(steps) (the whole
    file is written again: 1.4 ms a step on average over the 251 steps of the 20 x 40 benchmark,
    growing with the step count), the data of a step ~5 ms."""

    XML_EVERY = 1.0

    def __init__(self, path, points: np.ndarray, cells: list, xml_every: float | None = None):
        self.xml_every = self.XML_EVERY if xml_every is None else float(xml_every)
        self._w = _writer_class()(Path(path))
        self._w.__enter__()
        self._w.write_points_cells(points, cells)
        self._w.flush()
        self._xml_at = time.monotonic()

    def write(self, t: float, point_data: dict, cell_data: dict) -> None:
        self._w.write_data(t, point_data=point_data, cell_data=cell_data)
        now = time.monotonic()
        xml = now - self._xml_at >= self.xml_every
        self._w.flush(xml=xml)
        if xml:
            self._xml_at = now

    def close(self):
        if self._w is not None:
            self._w.__exit__()
            self._w = None


MODE_FIELDS = ("mode_ks", "mode_ks_f", "mode_detk", "mode_detk_f")


def nodal_vector(prob, u: np.ndarray) -> np.ndarray:
    """Full dof vector u (ndofs,) of ``prob`` (a Biaxial) -> (nnodes, 3) point field (x, y, 0),
    the layout ParaView warps by."""
    nd = np.asarray(prob.basis.nodal_dofs)
    out = np.zeros((prob.mesh.p.shape[1], 3))
    out[:, 0], out[:, 1] = u[nd[0]], u[nd[1]]
    return out


def mode_fields(prob, modes: dict) -> dict:
    """The point fields ``mode_ks``, ``mode_ks_f``, ``mode_detk``, ``mode_detk_f`` of one step, each
    (nnodes, 3): the mode (a full dof vector, from GlobalCheck) scaled to a largest nodal
    displacement of 1 (dimensionless) with its largest-magnitude component positive (the sign of an
    eigenvector is arbitrary), or zeros where the mode was not computed (the criterion did not fire
    at that step): every step carries the same fields."""
    out = {}
    for key in MODE_FIELDS:
        u = modes.get(key)
        f = np.zeros((prob.mesh.p.shape[1], 3))
        if u is not None:
            f = nodal_vector(prob, u)
            f /= np.max(np.linalg.norm(f, axis=1))
            if f.flat[np.argmax(np.abs(f))] < 0:
                f = -f
        out[key] = f
    return out


def cell_tensor(prob, t: np.ndarray) -> np.ndarray:
    """Element means of a (2, 2, npts) in-plane tensor -> (nel, 9), the 3 x 3 tensor row by row
    (XX XY XZ YX YY YZ ZX ZY ZZ, the 9-component XDMF "Tensor" ParaView names so); the
    out-of-plane components are 0 (the H-model is two-dimensional: strain is plane, and the
    stress is the in-plane tensor whose trace/2 is p)."""
    out = np.zeros((prob.nel, 3, 3))
    out[:, :2, :2] = prob.per_element(t.reshape(4, -1)).reshape(2, 2, prob.nel).transpose(2, 0, 1)
    return out.reshape(prob.nel, 9)


def plot_mode(path, prob, u: np.ndarray, title: str = "") -> None:
    """Figure of a displacement mode u (ndofs,) of ``prob``: left, the mesh deformed along the
    mode (largest nodal displacement drawn as 8 % of the specimen width), elements coloured by
    the norm of the mode's strain (relative to its largest element value), the imperfection
    outlined (the title says "perfect specimen" when there is none); right, the nodal arrows on
    the undeformed mesh, coloured by their length (relative to the largest), with its scale."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    U = nodal_vector(prob, u)[:, :2]
    U = U / np.max(np.linalg.norm(U, axis=1))
    eps = prob.strain(u)
    g = prob.per_element(np.sqrt(np.sum(eps.reshape(4, -1) ** 2, axis=0)))
    g = g / g.max()
    P, t = prob.mesh.p.T, prob.mesh.t.T
    amp = 0.08 * prob.width
    fig, axs = plt.subplots(1, 2, figsize=(9.5, 6.2))
    ax = axs[0]
    ax.add_collection(PolyCollection(P[t], facecolor="none", edgecolor="0.8", lw=0.4))
    pc = PolyCollection((P + amp * U)[t], array=g, cmap="viridis", edgecolor="k", lw=0.2)
    ax.add_collection(pc)
    weak = len(prob.weak_elements) > 0
    if weak:
        ax.add_collection(PolyCollection(P[t[prob.weak_elements]], facecolor="none",
                                         edgecolor="C3", lw=0.8))
    fig.colorbar(pc, ax=ax, shrink=0.7, label="strain of the mode, |eps| / max")
    ax.set_title(f"deformed along the mode (x {amp * 1e3:.1f} mm)\n"
                 + ("red outline: the imperfection" if weak else "perfect specimen"), fontsize=8)
    ax = axs[1]
    ax.add_collection(PolyCollection(P[t], facecolor="none", edgecolor="0.75", lw=0.4))
    q = ax.quiver(P[:, 0], P[:, 1], U[:, 0], U[:, 1], np.linalg.norm(U, axis=1), cmap="plasma",
                  angles="xy", scale_units="xy", scale=1.0 / amp, width=0.004)
    q.set_clim(0.0, 1.0)
    fig.colorbar(q, ax=ax, shrink=0.7, label="nodal displacement of the mode, |u| / max")
    ax.set_title(f"nodal displacement of the mode (arrows x {amp * 1e3:.1f} mm)", fontsize=8)
    for ax in axs:
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_xlabel("x [m]")
    axs[0].set_ylabel("y [m]")
    if title:
        fig.suptitle(title, fontsize=9)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def plot_curve(path, curve: dict, mp: dict | None = None, title: str = "",
               end: str | None = None) -> None:
    """q against eps1 (compression positive) with the first firing of each criterion marked:
    lam_min(K_s) <= 0 and the det K sign change (both platen controls), the first point with
    local W2 <= 0 and with Rice's indicator <= 0; beside the material-point curve. The markers are
    hollow and of growing sizes, so that criteria firing at the same step stay visible; the
    confining pressure (s2 of row 0) heads the title. ``end``: the outcome of a run that ended
    without a static state (its last row marked), and the material point's own end likewise
    (``mp["end"]``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    if mp is not None:
        ax.plot(100 * mp["eps1"], mp["q"] / 1e3, "k--", lw=1.2, zorder=3,
                label=r"material point (point.driver, $\delta\varepsilon_1$ = 1e-5)")
    e, q = 100 * curve["eps1"], curve["q"] / 1e3
    ax.plot(e, q, "o-", ms=2.5, lw=1, color="C0", label="FE specimen")
    if end is not None:
        ax.plot(e[-1], q[-1], "X", color="C1", ms=11, zorder=40,
                label=f"FE: no static state beyond ({end} at {e[-1]:.3f} %)")
    if mp is not None and mp.get("outcome", "complete") != "complete":
        ax.plot(100 * mp["eps1"][-1], mp["q"][-1] / 1e3, "kX", ms=9, zorder=40,
                label=f"material point: no static state beyond ({mp['outcome']})")
    marks = first_events(curve)
    style = {"lam_min_ks": ("v", "C1", r"first $\lambda_{min}(K_s) \leq 0$ (platen displ.)"),
             "det_k": ("s", "C3", r"first $\det K$ sign change (platen displ.)"),
             "lam_min_ks_f": ("^", "C2", r"first $\lambda_{min}(K_s) \leq 0$ (platen force)"),
             "det_k_f": ("D", "C4", r"first $\det K$ sign change (platen force)"),
             "local_w2": ("o", "C5", r"first local $W_2 \leq 0$ (some point)"),
             "local_rice": ("p", "C6", r"first local Rice $\det(n \cdot D \cdot n) \leq 0$")}
    for size, (key, (m, c, lab)) in zip(np.arange(7.0, 30.0, 2.5), style.items()):
        k = marks.get(key)
        if k is not None:
            ax.plot(e[k], q[k], m, color=c, ms=size, mfc="none", mew=1.6, zorder=4 + 30 - size,
                    label=rf"{lab}: $\varepsilon_1$ = {e[k]:.3f} %")
        else:
            ax.plot([], [], m, color=c, mfc="none", label=f"{lab}: not reached")
    ax.set_xlabel(r"axial strain $\varepsilon_1$ [%] (compression +)")
    ax.set_ylabel(r"$q = \sigma_1 - \sigma_2$ [kPa]")
    ax.grid(alpha=0.3)
    leg = ax.legend(fontsize=7, loc="lower right")
    for h in getattr(leg, "legend_handles", None) or getattr(leg, "legendHandles", []):
        if hasattr(h, "set_markersize"):
            h.set_markersize(7)           # one size in the legend; the sizes only separate the marks
    head = rf"$\sigma_2$ = {curve['s2'][0] / 1e3:g} kPa"
    ax.set_title(f"{head}, {title}" if title else head, fontsize=9)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def first_events(curve: dict) -> dict:
    """Row indices of the first lam_min_ks <= 0 and first det K sign change (vs row 0), for both
    platen controls, and of the first row with a local criterion <= 0 at some point
    (local_lam_Ds, local_w2, local_rice); a key is absent when the event does not happen."""
    out = {}
    for key, col in (("local_lam_Ds", "min_lam_Ds"), ("local_w2", "min_w2_local"),
                     ("local_rice", "min_rice")):
        k = np.flatnonzero(curve[col] <= 0)
        if k.size:
            out[key] = int(k[0])
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
