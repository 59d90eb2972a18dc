"""Specimen meshes: a rectangle made in code (quadrilaterals or triangles) or a file read by meshio.

Coordinates: x = lateral (material axis 2), y = vertical = axial (material axis 1); the specimen
occupies [0, width] x [0, height] [m] (a file mesh may sit anywhere: its bounding box is used).
The FE problem is per unit out-of-plane thickness (plane strain).
"""
from __future__ import annotations

import numpy as np
import skfem

__all__ = ["rectangle", "from_file", "from_meshio", "check_mesh", "MESH_KINDS"]

MESH_KINDS = ("quad", "tri")


def _positive(name, value, allowed="> 0"):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number {allowed}, got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name} = {value!r} is out of range: allowed {name} {allowed}")
    return v


def _count(name, value):
    if isinstance(value, bool) or not float(value) == int(value) or int(value) < 1:
        raise ValueError(f"{name} = {value!r} is out of range: allowed an integer {name} >= 1")
    return int(value)


def rectangle(width: float = 0.05, height: float = 0.1, nx: int = 10, ny: int = 20,
              kind: str = "quad") -> skfem.Mesh:
    """Structured mesh of [0, width] x [0, height] [m] with nx x ny cells.

    kind : "quad" (bilinear quadrilaterals, MeshQuad) or "tri" (each cell cut along one diagonal,
    MeshTri; the single diagonal direction biases shear bands, which is why quads are the default).
    """
    width = _positive("width", width, "> 0 [m]")
    height = _positive("height", height, "> 0 [m]")
    nx = _count("nx", nx)
    ny = _count("ny", ny)
    x = np.linspace(0.0, width, nx + 1)
    y = np.linspace(0.0, height, ny + 1)
    if kind == "quad":
        mesh = skfem.MeshQuad.init_tensor(x, y)
    elif kind == "tri":
        mesh = skfem.MeshTri.init_tensor(x, y)
    else:
        raise ValueError(f"mesh kind {kind!r} is not allowed: allowed {MESH_KINDS}")
    check_mesh(mesh.p, mesh.t, oriented=(kind == "quad"))
    return mesh


def check_mesh(p: np.ndarray, t: np.ndarray, oriented: bool = True) -> None:
    """Raise ValueError if an element is degenerate or inverted.

    p : (2, npoints) coordinates [m]; t : (nverts, nelems) corner indices in cyclic order.
    skfem integrates with |det J|, so a folded element would be silently accepted: here every
    corner of every element must turn the same way as the rest of the mesh (the cross product of
    the two edges at each corner has one sign everywhere), which rules out inverted triangles,
    inverted or non-convex (bow-tie) quadrilaterals and zero-area elements.
    oriented=False only checks |area| (skfem's own MeshTri sorts the corners of each triangle,
    which loses the orientation; a mesh file keeps it).
    """
    p = np.asarray(p, dtype=float)
    t = np.asarray(t)
    if p.ndim != 2 or p.shape[0] != 2:
        raise ValueError(f"mesh points must have shape (2, npoints), got {p.shape}")
    if t.ndim != 2 or t.shape[0] not in (3, 4) or t.shape[1] < 1:
        raise ValueError(f"mesh elements must be triangles or quadrilaterals (3 or 4 corners), "
                         f"got an element array of shape {t.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("mesh points contain non-finite coordinates")
    xy = p[:, t]                                   # (2, nverts, nelems)
    e_next = np.roll(xy, -1, axis=1) - xy          # edge leaving each corner
    e_prev = xy - np.roll(xy, 1, axis=1)           # edge arriving at each corner
    cross = e_prev[0] * e_next[1] - e_prev[1] * e_next[0]   # (nverts, nelems)
    size2 = np.max(np.sum(e_next ** 2, axis=0), axis=0)     # (nelems,) squared longest edge
    scale = np.where(np.sum(cross, axis=0) >= 0, 1.0, -1.0)
    majority = 1.0 if np.sum(scale > 0) >= np.sum(scale < 0) else -1.0
    if oriented:
        bad = np.any(majority * cross <= 1e-12 * size2, axis=0)
    else:
        bad = np.abs(np.sum(cross, axis=0)) <= 1e-12 * size2
    if np.any(bad):
        idx = np.flatnonzero(bad)
        raise ValueError(
            f"mesh has {idx.size} inverted, non-convex or degenerate element(s) (first: "
            f"{idx[:10].tolist()}): allowed elements have positive area and every corner "
            f"turning the same way as the rest of the mesh")


def from_meshio(m) -> skfem.Mesh:
    """skfem mesh from a meshio.Mesh holding triangles or quadrilaterals (2D or z = 0 points)."""
    import skfem.io.meshio as skio
    cells = {k: v for k, v in m.cells_dict.items() if len(v)}
    kind = "quad" if "quad" in cells else "triangle" if "triangle" in cells else None
    if kind is None:
        raise ValueError(f"mesh file must hold 'quad' or 'triangle' cells, got "
                         f"{list(cells) or 'no cells'}")
    pts = np.asarray(m.points, dtype=float)
    if pts.shape[1] == 3:
        if np.any(np.abs(pts[:, 2]) > 0):
            raise ValueError("mesh points must lie in the plane z = 0 (a 2D specimen)")
        pts = pts[:, :2]
    # Check before skfem sees it: MeshTri may reorder the corners and Basis uses |det J|.
    check_mesh(pts.T, np.asarray(cells[kind]).T)
    return skio.from_meshio(m, force_meshio_type=kind)


def from_file(path) -> skfem.Mesh:
    """Read a triangle or quadrilateral mesh with meshio (any format meshio reads). A missing
    file, a file meshio cannot read and a mesh without elements are ValueErrors."""
    import contextlib
    import io
    import os

    import meshio
    if not os.path.isfile(path):
        raise ValueError("no such file")
    said = io.StringIO()
    try:    # meshio prints its reasons and exits (SystemExit) or raises by format: say it once
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
            m = meshio.read(path)
    except (Exception, SystemExit) as e:
        why = (said.getvalue().strip() or str(e).strip() or type(e).__name__).splitlines()[0]
        raise ValueError(f"not a mesh meshio can read ({why}): allowed a triangle or "
                         "quadrilateral mesh file") from None
    return from_meshio(m)
