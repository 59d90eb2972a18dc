"""The files of dem: state save/load (npz), its tables (CSV, every float to the bit), VTK
snapshots (meshio).  Every write goes through the atomic writers of ``common.io`` (a temporary
file in the target directory, moved in place with os.replace), so an interrupted run never
leaves a half-written file under the final name.

State file format (npz, FORMAT_VERSION = 5), arrays:
  format ("dem-state"), format_version (int), params (JSON of DemParams),
  x, v (N,2), w, theta, r (N,), walls, walls_ref, prev (4,), x_ref (N,2),
  pi, pj (P,) int32, ft (P,), mr (P,) rolling-moment history, step, time, mu, mu_r, cap_on,
  ctrl_mode (2,), ctrl_s_from, ctrl_s_to (2,), ctrl_ramp (2,) [start, len], ctrl_rate,
  ctrl_len0 (2,), ctrl_ratio (R of the tied controls), ctrl_wall_mass (the walls' generalized
  mass under a dead load), ctrl_g_held (the dead load's held generalized force [N]), ref_len
  (2,), meta (JSON, free-form), and any named arrays saved with it (``array_<name>``: a
  checkpoint's energy ledger).
Version 1 (before rolling resistance) is still read: no mr, mu_r, and params without
rolling_friction / rolling_stiffness; it loads as a state without rolling resistance
(rolling_friction 0, rolling_stiffness its default, mr and mu_r zero), which is what it was.
Versions 1 and 2 (before the tied control) have no ctrl_ratio: it loads as 0, the value of
every control but the tied one.  (The version was raised so that code older than the tied
control refuses a file saved under it rather than running its mode 2 as strain control.)
Versions 1-3 (before the dead load) have no ctrl_wall_mass: it loads as 0, the value of every
control but the dead load (version 4, so that older code refuses a state saved under it).
Versions 1-4 have no ctrl_g_held: it loads as 0, except from a version-4 file under the dead
load, which held the force [N] in the y axis's stress targets (ctrl_s_from[1], ctrl_s_to[1]):
it moves to g_held and those targets load as 0, the control ``walls.dead_load`` makes now
(version 5, so that version-4 code refuses a file whose dead load it would read as no load).
"""
from __future__ import annotations

import csv
import io as _io
import json
import os
import zipfile

import numpy as np

from common.io import REPR, atomic_path, atomic_write_bytes
from common.io import write_csv as _write_csv

from .params import DemParams
from .simulation import State, Simulation
from .walls import DEAD, Control

FORMAT = "dem-state"
FORMAT_VERSION = 5
READ_VERSIONS = (1, 2, 3, 4, 5)
# what a version-1 file's params lacked: the values its runs had
V1_PARAMS = {"rolling_friction": 0.0, "rolling_stiffness": 1.0}


def save_state(path, state: State, meta: dict | None = None, arrays: dict | None = None):
    """Write a complete State to `path` (npz) atomically; ``arrays``: named arrays that go with
    it in the same file (a checkpoint's energy ledger), read back by ``load_state`` under
    ``meta["arrays"]``."""
    c = state.control
    buf = _io.BytesIO()
    np.savez(buf, format=np.array(FORMAT), format_version=np.array(FORMAT_VERSION),
             params=np.array(json.dumps(state.params.to_dict())),
             x=state.x, v=state.v, w=state.w, theta=state.theta, r=state.r,
             walls=state.walls, walls_ref=state.walls_ref, prev=state.prev, x_ref=state.x_ref,
             pi=state.pi, pj=state.pj, ft=state.ft, mr=state.mr, step=np.array(state.step),
             time=np.array(state.time), mu=np.array(state.mu), mu_r=np.array(state.mu_r),
             cap_on=np.array(state.cap_on),
             ctrl_mode=np.asarray(c.mode, np.int64), ctrl_s_from=np.asarray(c.s_from, float),
             ctrl_s_to=np.asarray(c.s_to, float),
             ctrl_ramp=np.array([c.ramp_start, c.ramp_len], np.int64),
             ctrl_rate=np.asarray(c.rate, float), ctrl_len0=np.asarray(c.len0, float),
             ctrl_ratio=np.array(float(c.ratio)), ctrl_wall_mass=np.array(float(c.wall_mass)),
             ctrl_g_held=np.array(float(c.g_held)),
             ref_len=state.ref_len, meta=np.array(json.dumps(meta or {})),
             **{"array_" + k: v for k, v in (arrays or {}).items()})
    atomic_write_bytes(path, buf.getvalue())


def save_unsound(exc, out_dir) -> str | None:
    """Keep the state of a run stopped on an unsound state (``dem.regime.UnsoundState``) as
    ``out_dir``/unsound_state.npz, its outcome, step and line in the meta; returns the path (None
    without a state or a folder)."""
    from .regime import KEPT
    if exc.state is None or not out_dir:
        return None
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, KEPT)
    save_state(path, exc.state, meta={"outcome": exc.outcome, "step": exc.step, "why": str(exc)})
    return path


_KEYS = ["format", "format_version", "params", "x", "v", "w", "theta", "r", "walls",
         "walls_ref", "prev", "x_ref", "pi", "pj", "ft", "step", "time", "mu", "cap_on",
         "ctrl_mode", "ctrl_s_from", "ctrl_s_to", "ctrl_ramp", "ctrl_rate", "ctrl_len0",
         "ref_len"]


def load_state(path) -> tuple[State, dict]:
    """Read a state file.  ValueError if it is missing, truncated, not a DEM state, or of
    another format version (allowed: READ_VERSIONS)."""
    if not os.path.isfile(path):
        raise ValueError(f"state file {path}: " + ("a folder" if os.path.isdir(path)
                                                    else "no such file"))
    if not zipfile.is_zipfile(path):      # np.load would try pickle and advise allow_pickle
        raise ValueError(f"state file {path}: not a DEM state (not an .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in _KEYS if k not in z.files]
            if missing:
                raise ValueError(f"state file {path}: not a DEM state (missing {missing})")
            d = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, OSError, KeyError) as e:
        raise ValueError(f"state file {path} is truncated or not a valid npz: {e}") from None
    except ValueError as e:
        if "state file" in str(e):
            raise
        raise ValueError(f"state file {path} is truncated or corrupt: {e}") from None
    if str(d["format"]) != FORMAT:
        raise ValueError(f"state file {path}: format={str(d['format'])!r}; allowed: {FORMAT!r}")
    ver = int(d["format_version"])
    if ver not in READ_VERSIONS:
        raise ValueError(f"state file {path}: format_version={ver}; allowed range: "
                         f"format_version in {READ_VERSIONS}")
    pd = json.loads(str(d["params"]))
    if ver == 1:
        if any(k in pd for k in V1_PARAMS):
            raise ValueError(f"state file {path}: format_version=1 with rolling parameters")
        pd.update(V1_PARAMS)
        d["mr"] = np.zeros(len(d["ft"]))
        d["mu_r"] = np.array(0.0)
    elif "mr" not in d or "mu_r" not in d:
        raise ValueError(f"state file {path}: not a DEM state (missing ['mr', 'mu_r'])")
    if ver >= 3 and "ctrl_ratio" not in d:
        raise ValueError(f"state file {path}: not a DEM state (missing ['ctrl_ratio'])")
    if ver >= 4 and "ctrl_wall_mass" not in d:
        raise ValueError(f"state file {path}: not a DEM state (missing ['ctrl_wall_mass'])")
    if ver >= 5 and "ctrl_g_held" not in d:
        raise ValueError(f"state file {path}: not a DEM state (missing ['ctrl_g_held'])")
    params = DemParams.from_dict(pd)
    n = len(d["r"])
    for k in ("x", "v", "x_ref"):
        if d[k].shape != (n, 2):
            raise ValueError(f"state file {path}: {k} has shape {d[k].shape}, expected ({n}, 2)")
    if not (len(d["pi"]) == len(d["pj"]) == len(d["ft"]) == len(d["mr"])):
        raise ValueError(f"state file {path}: inconsistent pair list lengths")
    ctrl = Control(tuple(int(a) for a in d["ctrl_mode"]), tuple(map(float, d["ctrl_s_from"])),
                   tuple(map(float, d["ctrl_s_to"])), int(d["ctrl_ramp"][0]),
                   int(d["ctrl_ramp"][1]), tuple(map(float, d["ctrl_rate"])),
                   tuple(map(float, d["ctrl_len0"])),
                   float(d["ctrl_ratio"]) if ver >= 3 else 0.0,
                   float(d["ctrl_wall_mass"]) if ver >= 4 else 0.0,
                   float(d["ctrl_g_held"]) if ver >= 5 else 0.0)
    if ver == 4 and ctrl.mode == (DEAD, DEAD):     # the held force [N] was in the stress targets
        ctrl = ctrl._replace(s_from=(ctrl.s_from[0], 0.0), s_to=(ctrl.s_to[0], 0.0),
                             g_held=ctrl.s_to[1])
    st = State(params, d["x"], d["v"], d["w"], d["theta"], d["r"], d["walls"], d["walls_ref"],
               d["prev"], d["x_ref"], d["pi"].astype(np.int32), d["pj"].astype(np.int32),
               d["ft"], d["mr"], int(d["step"]), float(d["time"]), float(d["mu"]),
               float(d["mu_r"]), bool(d["cap_on"]),
               ctrl, d["ref_len"])
    meta = json.loads(str(d["meta"])) if "meta" in d else {}
    extra = {k[len("array_"):]: v for k, v in d.items() if k.startswith("array_")}
    if extra:
        meta["arrays"] = extra
    return st, meta


def write_csv(path, header, rows):
    """A table of dem: header (list of names), rows (iterable of sequences), written by the one
    CSV writer (``common.io.write_csv``) in dem's number format (``REPR``: every float to the
    bit, other values as the csv module writes them)."""
    _write_csv(path, header, rows, fmt=REPR)


def read_csv(path):
    """(header, rows as list of dicts with float values where possible)."""
    with open(path, newline="") as f:
        rd = csv.DictReader(f)
        out = []
        for row in rd:
            rr = {}
            for k, v in row.items():
                try:
                    rr[k] = float(v)
                except (TypeError, ValueError):
                    rr[k] = v
            out.append(rr)
        return rd.fieldnames, out


def _atomic_meshio(path, mesh):
    import meshio
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu")


def write_particles_vtk(path, sim: Simulation):
    """Particles as VTK vertices (.vtu): radius [m], velocity [m/s], spin [rad/s],
    stress (per-particle sum f (x) (x_c - x_p) / particle volume [Pa], compression
    positive, flattened xx, xy, yx, yy)."""
    import meshio
    from . import kernels
    snap = sim.snapshot()
    s = kernels.particle_stress(sim.x, sim.r, snap.ci, snap.cj, snap.fx, snap.fy,
                                snap.wp, snap.ww, snap.wf)
    vol = np.pi * sim.r ** 2 * sim.params.thickness
    s = -s / vol[:, None, None]
    pts = np.column_stack([sim.x, np.zeros(sim.n)])
    mesh = meshio.Mesh(pts, [("vertex", np.arange(sim.n).reshape(-1, 1))],
                       point_data={"radius": sim.r.copy(),
                                   "velocity": np.column_stack([sim.v, np.zeros(sim.n)]),
                                   "spin": sim.w.copy(),
                                   "stress": s.reshape(-1, 4)})
    _atomic_meshio(path, mesh)


def write_contacts_vtk(path, sim: Simulation):
    """Contact network as VTK lines between particle centres with cell data
    normal_force [N] and tangential_force [N]."""
    import meshio
    snap = sim.snapshot()
    pts = np.column_stack([sim.x, np.zeros(sim.n)])
    lines = np.column_stack([snap.ci, snap.cj]).astype(np.int64)
    ft = np.hypot(snap.fx, snap.fy) ** 2 - snap.fn ** 2
    ft = np.sqrt(np.clip(ft, 0, None))
    mesh = meshio.Mesh(pts, [("line", lines)],
                       cell_data={"normal_force": [snap.fn.copy()], "tangential_force": [ft]})
    _atomic_meshio(path, mesh)
