"""The FE biaxial test end to end: build the specimen, step it, check bifurcation, write outputs.

``run_biaxial(BiaxialConfig(...), out_dir)`` is what ``python -m fem biaxial`` calls. Outputs in
``out_dir``: curve.csv (a row per converged step, row 0 = initial state), fields.xdmf + fields.h5,
newton.log (residual norms of every iterate), curve.png and summary.json (written at the end).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, asdict, field, replace
from pathlib import Path

import numba
import numpy as np

from hmodel import HParams
from common.io import atomic_write_bytes
from point.contract import MaterialError, material_of

from .adapter import stress_to_model, strain_to_model
from .indicators import GlobalCheck, GlobalCheckProcess, global_w2, local_indicators
from .mesh import _count, rectangle, from_file
from hmodel.params import record_params as record_hmodel_params
from common.paramfile import write_params

from .output import (CurveWriter, FieldWriter, plot_curve, first_events, cell_tensor, nodal_vector,
                     mode_fields, plot_mode)
from .problem import Biaxial, Imperfection
from point.onsets import NO_CLOSED_FORM, has_mechanism

from .reference import FE_CLOSED_FORMS, closed_form_onsets, material_point_curve
from .solver import LoadStepper, StaticLoss

__all__ = ["BiaxialConfig", "MATERIAL", "build_problem", "run_biaxial", "RunResult", "BURST_POINTER"]

# where a loss of the static state is made to happen dynamically
BURST_POINTER = ("held past such a point the specimen cannot stay at rest: python -m fem burst "
                 "makes this failure happen dynamically (docs/burst.md, docs/fem.md)")


@dataclass
class BiaxialConfig:
    """Every option of a biaxial run (SI units, angles in degrees, compression positive).

    width, height [m]; nx, ny cells; mesh_kind "quad" | "tri"; mesh_file (meshio-readable,
    overrides the generated mesh); eps1_max final axial strain; d_eps1 nominal step; the
    material: the H-model of the HParams fields below (kn ... fabric_b), or ``material``, a
    parameter record of any law of the contract (``point.material_of``: DPParams, ...), which
    then replaces those fields; sigma2 is the confining pressure = the material's p0 either way
    (``params()``, ``with_params(P)``, ``law()``); imperfection None | "spot" | "band" with
    imp_size (fraction of the width), the weak values imp_values (a dict field -> weak value,
    any law) and the H-model's imp_phi_g, imp_alpha0 (used for an H-model specimen only),
    imp_angle (band) [deg]; Newton rtol / max_iter / max_cutbacks; fields: write fields.xdmf;
    n_sphere: strain directions sampled for the local minimum of the normalized W2.
    """

    width: float = 0.05
    height: float = 0.1
    nx: int = 10
    ny: int = 20
    mesh_kind: str = "quad"
    mesh_file: str | None = None
    eps1_max: float = 0.025
    d_eps1: float = 1e-4
    kn: float = 1.0e6
    kt: float = 0.5e6
    phi_g: float = 20.0
    alpha0: float = 42.8
    r_g: float = 1.0e-3
    thickness: float | None = None
    n_dir: int = 180
    fabric_a: float = 0.0
    fabric_b: float = 0.0
    sigma2: float = 200.0e3
    imperfection: str | None = None
    imp_size: float = 0.1
    imp_phi_g: float | None = 18.0
    imp_alpha0: float | None = None
    imp_angle: float = 45.0
    rtol: float = 1e-10
    max_iter: int = 25
    max_cutbacks: int = 6
    fields: bool = True
    n_sphere: int = 600
    mp_reference: bool = True
    global_process: bool = True
    material: object = None
    imp_values: dict | None = None

    def validate(self) -> "BiaxialConfig":
        """Every field of the specimen, loading and solver out of its range raises ValueError
        "field = value is out of range: allowed ..." (``common.options.record_error`` names the
        option); the material is HParams's (``params()``), the weak zone Imperfection's."""
        def real(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        def count(v, lo):
            return isinstance(v, int) and not isinstance(v, bool) and v >= lo
        checks = (("width", real(self.width) and self.width > 0, "value > 0 [m]"),
                  ("height", real(self.height) and self.height > 0, "value > 0 [m]"),
                  ("nx", count(self.nx, 1), "an integer value >= 1"),
                  ("ny", count(self.ny, 1), "an integer value >= 1"),
                  ("mesh_kind", self.mesh_kind in ("quad", "tri"), "quad or tri"),
                  ("eps1_max", real(self.eps1_max) and 0 < self.eps1_max < 0.5,
                   "0 < value < 0.5"),
                  ("d_eps1", real(self.d_eps1) and 0 < self.d_eps1 < 0.05, "0 < value < 0.05"),
                  ("imperfection", self.imperfection in (None, "none", "spot", "band"),
                   "none, spot or band"),
                  ("imp_size", real(self.imp_size) and 0 < self.imp_size <= 1,
                   "0 < value <= 1 (a fraction of the width)"),
                  ("imp_angle", real(self.imp_angle), "a finite value [deg]"),
                  ("rtol", real(self.rtol) and 0 < self.rtol < 1, "0 < value < 1"),
                  ("max_iter", count(self.max_iter, 1), "an integer value >= 1"),
                  ("max_cutbacks", count(self.max_cutbacks, 0), "an integer value >= 0"),
                  ("n_sphere", count(self.n_sphere, 1), "an integer value >= 1"))
        for name, ok, allowed in checks:
            if not ok:
                raise ValueError(f"{name} = {getattr(self, name)!r} is out of range: allowed "
                                 f"{allowed}")
        if self.material is not None:
            try:
                material_of(self.material)
            except MaterialError:
                raise ValueError(f"material = {self.material!r} is out of range: allowed a "
                                 "parameter record of a registered law (HParams, DPParams, ...) "
                                 "or None (the H-model of the HParams fields)") from None
            self._check_sigma2()
        if self.imp_values is not None and not isinstance(self.imp_values, dict):
            raise ValueError(f"imp_values = {self.imp_values!r} is out of range: allowed a dict "
                             "of parameter fields -> weak values, or None")
        return self

    def _check_sigma2(self):
        # one confining pressure: a record's p0 is never replaced silently
        if self.material.p0 != self.sigma2:
            raise ValueError(f"sigma2 = {self.sigma2!r} is out of range: allowed the material's "
                             f"p0 = {self.material.p0!r} (the confining pressure is the "
                             "record's p0: with_params(P) sets both)")

    def params(self):
        """The material's parameter record, p0 = sigma2: the HParams of the fields, or
        ``material`` (whose p0 must be sigma2: ``with_params`` sets both)."""
        if self.material is None:
            return HParams(**{f: getattr(self, c) for c, f in MATERIAL.items()})
        self._check_sigma2()
        return self.material

    def law(self):
        """The law of the material (``point.contract.Material``)."""
        return material_of(self.params())

    def is_hmodel(self) -> bool:
        """The material is the H-model (its fields, options and records apply)."""
        return self.material is None or isinstance(self.material, HParams)

    def with_params(self, params) -> "BiaxialConfig":
        """This configuration with the material of ``params`` (sigma2 = its p0): an HParams sets
        the H-model fields (``material`` None), another law's record sets ``material``."""
        if isinstance(params, HParams):
            return replace(self, material=None, **{c: getattr(params, f) for c, f in MATERIAL.items()})
        return replace(self, material=params, sigma2=params.p0)

    def weak_values(self) -> dict:
        """The imperfection's weak values, field -> value: the H-model's imp_phi_g and
        imp_alpha0 (where not None) for an H-model specimen, then imp_values."""
        ch = {}
        if self.is_hmodel():
            ch = {k: v for k, v in (("phi_g", self.imp_phi_g), ("alpha0", self.imp_alpha0))
                  if v is not None}
        ch.update(self.imp_values or {})
        return ch

    def record(self) -> dict:
        """The configuration as summary.json records it: every field, but for a specimen of
        another law than the H-model, the material's record (its law's name and fields) in
        place of the H-model fields and options that do not apply to it."""
        d = asdict(self)
        if self.material is None:
            d.pop("material")
            return d
        for c in list(MATERIAL) + ["imp_phi_g", "imp_alpha0"]:
            if c != "sigma2":
                d.pop(c)
        d["material"] = {"law": material_of(self.material).name, **d["material"]}
        return d


def material_record(params) -> dict:
    """What the outputs say about the material of a run: the law's name and description, and
    what its records mean where the law differs from the H-model (summary.json's "material")."""
    law = material_of(params)
    rec = {"name": law.name, "description": law.description,
           "absent": law.absent()}
    if "patterns" not in law.provides:
        rec["sliding_fraction"] = ("the fraction of the points whose step loaded the material "
                                   "(plastic): the law has no sliding pattern")
        rec["open_fraction"] = "absent (the law has no open mechanisms)"
    if not law.tangent_is_rate:
        rec["criteria"] = ("the tangent criteria (local indicators, global check) are computed "
                           "from the law's rate tangent at each converged state, not from the "
                           "step's consistent tangent")
    return rec


# the material fields of BiaxialConfig -> HParams field (sigma2, the confining pressure, is p0)
MATERIAL = {"kn": "kn", "kt": "kt", "phi_g": "phi_g", "alpha0": "alpha0", "r_g": "r_g",
            "thickness": "thickness", "n_dir": "n_dir", "fabric_a": "fabric_a",
            "fabric_b": "fabric_b", "sigma2": "p0"}


def build_problem(cfg: BiaxialConfig) -> Biaxial:
    """Mesh + material + boundary conditions of ``cfg`` (validates every option)."""
    params = cfg.params()
    if cfg.mesh_file:
        mesh = from_file(cfg.mesh_file)
    else:
        mesh = rectangle(cfg.width, cfg.height, cfg.nx, cfg.ny, cfg.mesh_kind)
    imp = None
    if cfg.imperfection not in (None, "", "none"):
        imp = Imperfection(kind=cfg.imperfection, size=cfg.imp_size, phi_g=None, alpha0=None,
                           values=cfg.weak_values(), angle=cfg.imp_angle)
    return Biaxial(mesh, params, imperfection=imp)


@dataclass
class RunResult:
    curve: dict
    events: dict
    summary: dict
    timings: dict
    out_dir: Path | None = None
    problem: object = None
    steps: list = field(default_factory=list)
    u: np.ndarray | None = None          # final (last converged) nodal displacement [m]


def _cells(prob):
    kind = "quad" if prob.mesh.t.shape[0] == 4 else "triangle"
    return [(kind, np.ascontiguousarray(prob.mesh.t.T))]


def _step_record(prob: Biaxial, stepper: LoadStepper, trial, f_int, info, n_sphere, t_start,
                 check, times: dict):
    """One CSV row and the field data of a converged state, but for the global indicators:
    its stiffness is submitted to ``check`` (GlobalCheck or GlobalCheckProcess) and
    ``_finish_record`` adds them; adds the seconds spent to times["global"], ["local"].

    The criteria are those of the rate problem at the converged state: the global check's K and
    the local indicators are built from ``MaterialField.rate_tangent`` (the step's consistent
    tangent itself for a law whose step tangent is its rate tangent, the H-model; the law's
    rate tangent in the step's direction otherwise, e.g. the Drucker-Prager's D, whose
    consistent tangent differs by O(G d lambda / tau))."""
    mat = prob.material
    s_m = stress_to_model(trial.sigma)                       # (2, 2, P) compression +
    s1 = -prob.platen_force(f_int) / prob.width
    s2 = float(prob.volume_average(s_m[1, 1]))
    q, p = s1 - s2, 0.5 * (s1 + s2)
    t0 = time.perf_counter()
    D = mat.rate_tangent(trial)
    check.submit(prob.stiffness(D))
    t1 = time.perf_counter()
    times["global"] += t1 - t0
    df_int = info["df_int"]
    df_ext = np.zeros_like(df_int)        # reactions on prescribed dofs; f_lat is a dead load
    df_ext[prob.prescribed] = df_int[prob.prescribed]
    w2 = global_w2(info["du"], df_int, df_ext)
    loc = local_indicators(D, n_sphere=n_sphere,
                           one_thread=isinstance(check, GlobalCheckProcess))
    times["local"] += time.perf_counter() - t1
    eps_fe = prob.strain(stepper.u)
    row = dict(step=stepper.step, eps1=stepper.eps1, s1=s1, s2=s2, q=q, p=p, eta=q / p,
               newton_iters=info.get("iters", 0), cutbacks=info.get("cutbacks", 0),
               d_eps1=info.get("d_eps1", 0.0), final_residual=info.get("residual", 0.0),
               min_det_D=loc["det_D"].min(), min_det_Ds=loc["det_Ds"].min(),
               min_lam_Ds=loc["lam_min_Ds"].min(), min_w2_local=loc["w2_min"].min(),
               min_rice=loc["rice_min"].min(),
               n_pts_w2_neg=int(np.count_nonzero(loc["w2_min"] <= 0)),
               n_pts_rice_neg=int(np.count_nonzero(loc["rice_min"] <= 0)),
               sliding_fraction=float(prob.volume_average(trial.sliding)),
               open_fraction=(float(prob.volume_average(trial.opened))
                              if trial.opened is not None else None),    # absent: an empty cell
               eps2_mean=float(prob.volume_average(strain_to_model(eps_fe)[1, 1])),
               time_s=time.perf_counter() - t_start)
    # fields: displacement (and the modes, _finish_record) at nodes; element means of stress /
    # strain (tensors, FE convention: tension positive, named so), element minima of the
    # indicators
    point = {"displacement": nodal_vector(prob, stepper.u)}
    cell = {"stress_tension_positive": cell_tensor(prob, trial.sigma),
            "strain_tension_positive": cell_tensor(prob, eps_fe),
            "q": prob.per_element(s_m[0, 0] - s_m[1, 1]),
            "p": prob.per_element(0.5 * (s_m[0, 0] + s_m[1, 1])),
            "sliding_fraction": prob.per_element(trial.sliding)}
    if trial.opened is not None:
        cell["open_fraction"] = prob.per_element(trial.opened)
    for k in ("det_D", "det_Ds", "lam_min_Ds", "w2_min", "rice_min"):
        cell[k] = prob.per_element(loc[k], how="min")
    weak = np.zeros(prob.nel)
    weak[prob.weak_elements] = 1.0
    cell["weak"] = weak
    return (row, w2, point,
            {k: [np.ascontiguousarray(v, dtype=float)] for k, v in cell.items()})


def _finish_record(prob: Biaxial, check, row: dict, w2: dict, point: dict, times: dict) -> dict:
    """Take the global indicators of the step ``_step_record`` submitted: into ``row`` (after
    its other columns, then the global W2) and ``point`` (the mode fields); returns the modes
    (full dof vectors or None, see GlobalCheck)."""
    t0 = time.perf_counter()
    g, modes = check.result()
    times["global"] += time.perf_counter() - t0
    row.update(g)
    row.update(w2)
    point.update(mode_fields(prob, modes))
    return modes


EVENT_LABELS = {
    "lam_min_ks": "global lam_min(K_s) <= 0, platen displacement-controlled",
    "det_k": "global det K sign change, platen displacement-controlled",
    "lam_min_ks_f": "global lam_min(K_s) <= 0, platen force-controlled",
    "det_k_f": "global det K sign change, platen force-controlled (limit point)",
    "local_lam_Ds": "local: lam_min(D_s) <= 0 at some point",
    "local_w2": "local: sampled min normalized W2 <= 0 at some point",
    "local_rice": "local: Rice min det(n.D.n) <= 0 at some point",
    "fe_peak": "FE specimen: peak of q",
}


def summarize(curve: dict, mp: dict | None, exact: dict | None = None,
              d_eps1: float | None = None) -> tuple[dict, dict]:
    """(events: name -> row index, summary dict) for the curve columns; with ``exact``
    (``reference.closed_form_onsets``: a law with a single mechanism) each event beside its
    closed form (``FE_CLOSED_FORMS``): "closed_form" {eps1, eta}, "difference" in eps1 and in
    load steps of ``d_eps1``, and what the closed form is to this criterion."""
    ev = first_events(curve)
    kq = int(np.argmax(curve["q"]))
    if kq < len(curve["q"]) - 1:
        ev["fe_peak"] = kq
    summ = {"events": {}, "material_point": None}
    for key, label in EVENT_LABELS.items():
        if key in ev:
            k = ev[key]
            summ["events"][key] = {"label": label, "row": k, "step": int(curve["step"][k]),
                                   "eps1": float(curve["eps1"][k]), "eta": float(curve["eta"][k]),
                                   "q": float(curve["q"][k])}
        else:
            summ["events"][key] = {"label": label, "row": None}
        if exact is not None and key in FE_CLOSED_FORMS:
            which, what = FE_CLOSED_FORMS[key]
            cf = exact.get(which)
            e = summ["events"][key]
            e["closed_form"] = dict(cf, h=which, meaning=what) if cf else {"h": which, "meaning": what,
                                                                          "eps1": None, "eta": None}
            if cf and e["row"] is not None:
                d = e["eps1"] - cf["eps1"]
                e["difference"] = {"eps1": d, "steps": d / d_eps1 if d_eps1 else None}
    summ["closed_forms"] = ("each event's closed form under the homogeneous specimen's control"
                            if exact is not None else NO_CLOSED_FORM)
    if mp is not None:
        summ["material_point"] = {"eps1_peak": mp["eps1_peak"], "eta_peak": mp["eta_peak"],
                                  "q_peak": mp["q_peak"], "peak_reached": bool(mp["peak_is_interior"])}
    return ev, summ


def _material_title(params) -> str:
    """The material in a figure's title: the law's name, and n_dir for the H-model."""
    law = material_of(params)
    return f"n_dir = {params.n_dir}" if isinstance(params, HParams) else law.name


def _flags_text(law) -> str:
    """What newton.log counts between iterates: the law's flags (``Material.flags_changed``)."""
    return ("hexagon flags" if "patterns" in law.provides
            else "points whose plastic flag")


def record_params(out_dir, params, note="") -> str:
    """Write ``params`` (any law) to ``out_dir``/params.json, the --params format, so that
    ``--params out_dir/params.json`` repeats the run: the H-model's file as
    ``hmodel.params.record_params`` writes it, another law's with its name as "model" and its
    units (``common.paramfile.write_params``). Returns the file name."""
    if isinstance(params, HParams):
        return record_hmodel_params(out_dir, params, note)
    law = material_of(params)
    write_params(Path(out_dir) / "params.json", params, law.name, law.units, note)
    return "params.json"


def format_summary(summ: dict) -> str:
    """The table of the criteria: where each first fires (eps1 [%], eta), and the material
    point's peak, in columns as wide as the longest label."""
    mp = summ["material_point"]
    mp_label = "material point (point.driver, d_eps1 = 1e-5): peak of q"
    w = max([len(e["label"]) for e in summ["events"].values()] + [len(mp_label)])
    exact = any("closed_form" in e for e in summ["events"].values())
    lines = [f"{'criterion':<{w + 2}s}  eps1 [%]     eta"
             + ("  closed form: h       eps1 [%]     eta  difference [steps]" if exact else "")]
    for key, e in summ["events"].items():
        row = (f"  {e['label']:<{w}s}  not reached       " if e["row"] is None else
               f"  {e['label']:<{w}s}  {100 * e['eps1']:8.4f}  {e['eta']:.4f}")
        cf = e.get("closed_form")
        if cf is not None:
            row += (f"  {cf['h']:>14s}  " + (f"{100 * cf['eps1']:8.4f}  {cf['eta']:.4f}"
                                             if cf["eps1"] is not None else "not reached     "))
            if e.get("difference"):
                row += f"  {e['difference']['steps']:+8.2f}"
        lines.append(row)
    if mp is not None:
        tag = "" if mp["peak_reached"] else " (not reached: end of the computed range)"
        lines.append(f"  {mp_label:<{w}s}  {100 * mp['eps1_peak']:8.4f}  {mp['eta_peak']:.4f}{tag}")
    return "\n".join(lines)


def run_biaxial(cfg: BiaxialConfig, out_dir=None, progress=None, params_note=None) -> RunResult:
    """Run the biaxial test of ``cfg``. With ``out_dir`` write the outputs there as the steps
    converge, and its material as params.json first (``--params out_dir/params.json`` repeats
    it; ``params_note``: where the values came from, also in summary.json); ``progress`` is a
    callable taking one line of text (None: silent).

    A step that fails after every cut-back is decided by ``solver.static_scan``: a static state
    further on continues the run; none under the platen's control ends it as a result
    (summary "outcome": 'uncontrollable' or 'discontinuous', "end": where and why; the last row
    the last converged state); undecided, RuntimeError. The converged steps are on disk.
    """
    _count("n_sphere", cfg.n_sphere)      # 0 divides by zero, < 0 turns the local W2 check off
    t_start = time.perf_counter()
    prob = build_problem(cfg)
    stepper = LoadStepper(prob, cfg.d_eps1, rtol=cfg.rtol, max_iter=cfg.max_iter,
                          max_cutbacks=cfg.max_cutbacks)
    if not (np.isfinite(cfg.eps1_max) and 0 < cfg.eps1_max < 0.5):
        raise ValueError(f"eps1_max = {cfg.eps1_max!r} is out of range: allowed 0 < eps1_max < 0.5")
    out = Path(out_dir) if out_dir is not None else None
    writer = fields = logf = None
    rows = []
    t_ind = {"indicators_output": 0.0, "global": 0.0, "local": 0.0}
    # the global check in a process of its own where Numba has more than one thread (then
    # there is a core for it; see GlobalCheckProcess); the same rows either way
    check = (GlobalCheckProcess.start(prob)
             if cfg.global_process and numba.config.NUMBA_NUM_THREADS > 1 else None) \
        or GlobalCheck(prob)
    first_mode = []     # mode_ks[_f].png drawn once each, at the first lam_min(K_s[_f]) <= 0
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        record_params(out, prob.params, "python -m fem biaxial" + (f"; {params_note}" if params_note else ""))
        writer = CurveWriter(out / "curve.csv")
        logf = open(out / "newton.log", "w")
        logf.write("# step d_eps1 | normalized residual |r|/(sigma2 H) of each iterate | "
                   f"{_flags_text(prob.law)} switched between iterates\n")
        if cfg.fields:
            fields = FieldWriter(out / "fields.xdmf", prob.mesh.p.T, _cells(prob))

    def log(msg):
        if logf is not None:
            logf.write(msg + "\n")
            logf.flush()
        if progress is not None:
            progress(msg)

    stepper.log = log

    def write(row, pdata, cdata, modes) -> str:
        """Write a complete row (CSV, fields, the first mode figures); returns its progress line."""
        if writer is not None:
            writer.write(row)
        if fields is not None:
            fields.write(row["eps1"], pdata, cdata)
        for suf, control in (("", "displ."), ("_f", "force")):
            if out is not None and suf not in first_mode and modes.get("mode_ks" + suf) is not None:
                first_mode.append(suf)
                plot_mode(out / f"mode_ks{suf}.png", prob, modes["mode_ks" + suf],
                          title=(rf"eigenvector of $\lambda_{{min}}(K_s)$ = "
                                 f"{row['lam_min_ks' + suf]:.4g} Pa, platen {control}, step "
                                 rf"{row['step']}, $\varepsilon_1$ = {100 * row['eps1']:.3f} %"))
        return (f"step {row['step']:4d} eps1 = {100 * row['eps1']:7.4f} % q = {row['q'] / 1e3:9.3f} kPa "
                f"eta = {row['eta']:.4f} it = {row['newton_iters']} cut = {row['cutbacks']} "
                f"sign det K (platen displ./force) = {row['det_k_sign']:+d}/{row['det_k_sign_f']:+d} "
                f"lam_min(K_s) (displ./force) = {row['lam_min_ks']:.3e}/{row['lam_min_ks_f']:.3e} Pa "
                f"W2 = {row['w2_global']:+.3f} {slide} = {row['sliding_fraction']:.3f} "
                f"t = {row['time_s']:.1f} s")

    slide = "slide" if "patterns" in prob.law.provides else "plastic"
    pending = []        # the last complete row, written while the next step is checked

    def flush(announce: bool):
        """Write the pending row (at the end of the run, whatever ends it: complete, its global
        check done); its progress line with ``announce``."""
        if pending:
            t0 = time.perf_counter()
            line = write(*pending.pop())
            t_ind["indicators_output"] += time.perf_counter() - t0
            if announce and progress is not None:
                progress(line)

    def emit(trial, f_int, info):
        # the global check of this step runs (in the check's process, if any) while this one
        # does the local indicators and writes the previous row
        t0 = time.perf_counter()
        row, w2, pdata, cdata = _step_record(prob, stepper, trial, f_int, info, cfg.n_sphere,
                                             t_start, check, t_ind)
        line = write(*pending.pop()) if pending else None
        modes = _finish_record(prob, check, row, w2, pdata, t_ind)
        rows.append(row)
        pending.append((row, pdata, cdata, modes))
        t_ind["indicators_output"] += time.perf_counter() - t0
        if line is not None and progress is not None:
            progress(line)

    steps = []

    def on_step(res, info):
        info = dict(info, iters=res.iterations, residual=res.residuals[-1])
        steps.append({"residuals": res.residuals, "pattern_changes": res.pattern_changes})
        if logf is not None:
            logf.write(f"{stepper.step} {info['d_eps1']:.3e} | "
                       + " ".join(f"{r:.3e}" for r in res.residuals) + " | "
                       + " ".join(str(c) for c in res.pattern_changes) + "\n")
            logf.flush()
        emit(res.trial, res.f_int, info)

    error = loss = None
    ended = False       # the steps ended (done, or a step failed), not an interrupt
    try:
        # row 0: the isotropic initial state, tangent of a zero increment
        trial0 = prob.material.trial(np.zeros((2, 2, prob.npts)))
        zero = np.zeros(prob.ndofs)
        emit(trial0, stepper.f_int, {"du": zero, "df_int": zero})
        try:
            stepper.run(cfg.eps1_max, on_step)
        except RuntimeError as e:
            error = e
            log(f"FAILED: {e}")
        except StaticLoss as e:
            # no static state beyond under the platen's control: the run's result, not an error
            loss = e.verdict
            log(f"ENDED: {e}")
        ended = True
    finally:        # whatever ends the run (also Ctrl-C, SIGTERM): the writers close, complete
        try:
            flush(announce=ended)     # interrupted: the row is written, no progress line
        finally:
            check.close()
        if writer is not None:
            writer.close()
        if fields is not None:
            fields.close()
    curve = {k: np.array([np.nan if r.get(k) is None else r[k] for r in rows], dtype=float)
             for k in rows[0]}
    mech = has_mechanism(material_of(prob.params))
    mp = (material_point_curve(prob.params, max(cfg.eps1_max, 1e-4), keep_states=mech)
          if cfg.mp_reference else None)
    exact = closed_form_onsets(prob.params, mp["path"]) if mp is not None and mech else None
    events, summ = summarize(curve, mp, exact, cfg.d_eps1)
    timings = dict(stepper.times, total=time.perf_counter() - t_start,
                   indicators_output=t_ind["indicators_output"], global_indicators=t_ind["global"],
                   local_indicators=t_ind["local"],
                   steps=stepper.step, points=prob.npts)
    if cfg.is_hmodel():
        timings["n_dir"] = prob.params.n_dir
    summ["timings"] = timings
    summ["config"] = cfg.record()
    summ["parameters"] = params_note
    summ["material"] = material_record(prob.params)
    summ["completed"] = error is None
    summ["outcome"] = "complete" if loss is None and error is None else (
        loss.outcome if loss is not None else "error")
    summ["end"] = None if loss is None else {
        "line": loss.line(prob.height), "eps1": loss.delta_max / prob.height,
        "eps1_last_row": float(curve["eps1"][-1]), "det_k_ff_sign": list(loss.det_sign),
        "lam_min_ks_ff": list(loss.lam_min), "w2": list(loss.w2), "scan_points": loss.points,
        "burst": BURST_POINTER}
    if mp is not None:
        summ["material_point"]["outcome"] = mp["outcome"]
        summ["material_point"]["end"] = mp["end"] if mp["outcome"] != "complete" else None
    if out is not None:
        plot_curve(out / "curve.png", curve, mp,
                   title=f"{prob.nel} elements, {prob.npts} points, {_material_title(prob.params)}",
                   end=loss.outcome if loss is not None else None)
        atomic_write_bytes(out / "summary.json", json.dumps(summ, indent=1, default=float).encode())
        logf.close()
    result = RunResult(curve, events, summ, timings, out, prob, steps, stepper.u.copy())
    if error is not None:
        error.result = result
        raise error
    return result
