"""Command line: ``python -m fem biaxial|burst ... --out DIR`` (over fem.biaxial.run_biaxial
and fem.burst.run_burst), its options from the vocabulary of ``common.options``."""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys

import numpy as np

from common import options as opt
from hmodel import params as hp
from point.experiment import compile_kernels

from .biaxial import MATERIAL, BiaxialConfig, run_biaxial, format_summary, record_params
from .burst import BurstConfig, run_burst

# Numba's OpenMP threads spin-wait after each parallel region of the material update (libgomp's
# default, ~5 ms with this CPU's slow `pause`), on the core where the run's global check then
# runs in its own process (fem.indicators.GlobalCheckProcess): measured, its checks took 13-16
# ms instead of 7-10 and the run 13.3 s instead of 10.8 (20 x 40 quads). Passive: idle threads
# sleep at once (the update itself measured no slower). libgomp reads this when the first
# parallel region starts, after these imports (they run none); a value set by the user is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

# memory of one quadrature point per hexagon orientation [bytes]: committed and trial states and
# the update's outputs (10 floats + 2 flags each, about 4 copies alive during a Newton iteration)
POINT_BYTES_PER_DIR = 4 * (10 * 8 + 2)
# the rest of one quadrature point [bytes]: stresses, tangents, B-matrices, its share of the
# sparse stiffness and its factorizations. Together: 66 kB a point at 180 orientations, as
# measured (peak RSS of 20 x 40 quads 160 MB above that of 10 x 20)
POINT_BYTES = 7_000
# the state of one quadrature point of a law without orientations (Drucker-Prager: strain,
# stress, plastic strain, kappa, a flag) [bytes], about 4 copies alive as above
STATE_BYTES = 4 * 14 * 8

# the default of an option that applies to the H-model only (--imp-phi-g, --imp-alpha0): given
# or not is what refuses it for another law's specimen
NOT_GIVEN = type("NotGiven", (), {"__repr__": lambda self: "not given"})()
# the options of the H-model alone, beside its parameters' (hmodel.params.PARAM_OPTIONS)
HMODEL_ONLY = (("--imp-phi-g", "imp_phi_g"), ("--imp-alpha0", "imp_alpha0"))


def _opt_float(s):
    return None if s.lower() == "none" else opt.real()(s)


_opt_float.__name__ = "real or none"


def _weak_values(text) -> dict:
    """--imp-values "mu_p=0.5,G=30e6" -> {"mu_p": 0.5, "G": 30e6} (the fields are checked
    against the specimen's record later)."""
    out = {}
    for part in (x.strip() for x in text.split(",")):
        if not part:
            continue
        name, eq, value = part.partition("=")
        name = name.strip()
        try:
            v = float(value)
        except ValueError:
            v = None
        if not (eq and name.isidentifier() and v is not None and np.isfinite(v)):
            raise ValueError(f"{part!r}: allowed FIELD=VALUE,... with finite values (e.g. "
                             "mu_p=0.5)")
        if name in out:
            raise ValueError(f"{name} is given twice: allowed each field once")
        out[name] = v
    if not out:
        raise ValueError(f"{text!r}: allowed FIELD=VALUE,... (one or more)")
    return out


_weak_values = opt.argtype(_weak_values, "FIELD=VALUE list")


def _specimen_options(sub, d: BiaxialConfig, eps1_max: bool):
    """The options both commands share: mesh, loading (``--eps1-max`` with ``eps1_max``),
    material, imperfection, and the Newton options in the group "solver and output", which is
    returned for the command's own output options. The values are checked by BiaxialConfig
    (``check_config``), the material by HParams."""
    add = opt.add
    BC = "BiaxialConfig"
    g = sub.add_argument_group("mesh")
    add(g, "--nx", d.nx, record=BC)
    add(g, "--ny", d.ny, record=BC)
    add(g, "--width", d.width, record=BC)
    add(g, "--height", d.height, record=BC)
    add(g, "--mesh", d.mesh_kind, record=BC, dest="mesh_kind", choices=["quad", "tri"])
    add(g, "--mesh-file", default_text="none (the generated mesh)")
    g = sub.add_argument_group("loading")
    if eps1_max:
        add(g, "--eps1-max", d.eps1_max, record=BC)
    add(g, "--d-eps1", d.d_eps1, record=BC,
        note="" if eps1_max else "of the drained path to the start states")
    add(g, "--sigma2", record="HParams", default_text="the p0 of --params FILE, else 200e3")
    hp.add_param_options(sub, file_note="of any law (its \"model\": hmodel, drucker-prager): "
                         "python -m hmodel params --out FILE writes the H-model's; the H-model's "
                         "options below apply to an H-model file only")
    g = sub.add_argument_group("imperfection")
    add(g, "--imperfection", "none", record=BC, choices=["none", "spot", "band"])
    add(g, "--imp-size", d.imp_size, record=BC)
    add(g, "--imp-values", record=BC, parse=_weak_values,
        default_text="none (for the H-model: --imp-phi-g, --imp-alpha0)")
    add(g, "--imp-phi-g", NOT_GIVEN, record=BC, parse=_opt_float,
        default_text=f"{d.imp_phi_g:g} (H-model only)")
    add(g, "--imp-alpha0", NOT_GIVEN, record=BC, parse=_opt_float,
        default_text="none (the specimen's; H-model only)")
    add(g, "--imp-angle", d.imp_angle, record=BC)
    g = sub.add_argument_group("solver and output")
    add(g, "--rtol", d.rtol, record=BC)
    add(g, "--max-iter", d.max_iter, record=BC)
    add(g, "--max-cutbacks", d.max_cutbacks, record=BC)
    return g


DESCRIPTION = """The plane-strain FE biaxial specimen (scikit-fem) with a material of any law at
every quadrature point (the H-model by default; --params FILE of another law, e.g.
drucker-prager). python -m fem COMMAND --help lists a command's options, each with its unit and
default. --out is required: a folder that records the command that wrote it (command.json);
another command refuses that folder unless --force."""


def build_parser() -> argparse.ArgumentParser:
    d = BiaxialConfig()
    ap = opt.Parser(prog="python -m fem", description=DESCRIPTION)
    sub = ap.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    b = sub.add_parser("biaxial", help="plane-strain FE biaxial test with global and local "
                       "bifurcation checks (det K, K_s, W2)")
    opt.add_out(b)
    g = _specimen_options(b, d, eps1_max=True)
    opt.add(g, "--no-fields", dest="fields", flag_value=False)
    opt.add(g, "--n-sphere", d.n_sphere, record="BiaxialConfig")
    opt.add_quiet(g)
    _burst_parser(sub)
    return ap


def _burst_parser(sub):
    """``python -m fem burst``: the options of docs/burst.md beside the specimen's."""
    c = BurstConfig()
    add = opt.add
    b = sub.add_parser("burst", help="the burst of kinetic energy: proportional strain paths, "
                       "then the conjugate force held (docs/burst.md)",
                       description="From the drained FE path, the proportional strain path d eps2 "
                       "= R d eps1 under the tie (platens on the four faces), then G held at "
                       "G_switch + dG just below and just past the c peak, in dynamics (Newmark "
                       "average acceleration); outcome by hmodel.burst_rule. See docs/burst.md "
                       "and docs/fem.md.")
    opt.add_out(b)
    g = b.add_argument_group("burst")
    BC = "BurstConfig"
    add(g, "--ratios", list(c.ratios), record=BC)
    add(g, "--start-fractions", list(c.start_fractions), record=BC,
        note="of the material point's drained peak eta, each < 1")
    add(g, "--dc", record=BC, default_text="1e-4 sigma2")
    add(g, "--density", c.density, record=BC, note="bulk, of the specimen")
    add(g, "--damping-ratio", c.damping_ratio, record=BC)
    add(g, "--steps-per-period", c.steps_per_period, record=BC)
    add(g, "--path-strain", c.path_strain, record=BC)
    add(g, "--path-d-eps1", c.path_d_eps1, record=BC)
    g = _specimen_options(b, c.specimen, eps1_max=False)
    add(g, "--no-fields", dest="fields", flag_value=False)
    opt.add_quiet(g)


def _param_error(e, cfg: BiaxialConfig, options=None):
    """The OptionError of a parameter record's ParamError ``e`` (any law): the H-model's names
    its option (``hp.param_option_error``); another law's p0 is --sigma2, its other fields come
    from --params FILE (``options``: a field's option where one sets it)."""
    if cfg.is_hmodel():
        return hp.param_option_error(e, options)
    opt_name = (options or {}).get(e.name) or ("--sigma2" if e.name == "p0" else
                                              f"--params ({e.name})")
    return opt.OptionError(f"{opt_name} {e.value!r} is out of range: allowed {e.allowed}")


def check_config(cfg: BiaxialConfig) -> None:
    """Everything ``run_biaxial`` would refuse, refused here first as an OptionError naming the
    command-line option: the material (--sigma2 for p0) and weak-zone parameters, the mesh file
    (missing, unreadable, no cells, bad elements) and the memory the run would need."""
    from point.contract import ParamError as LawParamError
    from .mesh import from_file
    from .problem import Imperfection
    try:
        cfg.validate()
    except ValueError as e:
        raise opt.record_error(e, "BiaxialConfig") from None
    try:
        base = cfg.params()
    except (hp.ParamError, LawParamError) as e:
        raise _param_error(e, cfg) from None
    if cfg.imperfection is not None:
        weak = cfg.weak_values()
        what = (f"--imp-values {','.join(f'{k}={v:g}' for k, v in (cfg.imp_values or {}).items())}"
                if cfg.imp_values else "--imp-phi-g / --imp-alpha0")
        if not weak:
            raise opt.OptionError(
                f"--imperfection {cfg.imperfection}: no weak value: allowed --imp-values "
                "FIELD=VALUE,..." + (" (or --imp-phi-g, --imp-alpha0)" if cfg.is_hmodel() else
                                     f" of the {cfg.law().name} specimen's fields"))
        try:
            Imperfection(kind=cfg.imperfection, size=cfg.imp_size, phi_g=None, alpha0=None,
                         values=weak, angle=cfg.imp_angle).params(base)
        except (hp.ParamError, LawParamError) as e:
            option = {"phi_g": "--imp-phi-g", "alpha0": "--imp-alpha0"} if cfg.is_hmodel() else {}
            if cfg.imp_values and e.name in cfg.imp_values:
                option = {e.name: f"--imp-values {e.name}="}
            raise _param_error(e, cfg, option) from None
        except ValueError as e:
            raise opt.OptionError(f"--imperfection {cfg.imperfection} ({what}): {e}") from None
    hmodel = cfg.is_hmodel()
    if cfg.mesh_file:
        opt.check_file(cfg.mesh_file, "--mesh-file", "a triangle or quadrilateral mesh file "
                       "meshio can read")
        try:
            mesh = from_file(cfg.mesh_file)
        except ValueError as e:
            raise opt.OptionError(f"--mesh-file {cfg.mesh_file}: {e}") from None
        npts, options = mesh.t.shape[1] * (4 if mesh.t.shape[0] == 4 else 1), "--mesh-file"
    else:
        npts, options = cfg.nx * cfg.ny * (4 if cfg.mesh_kind == "quad" else 2), "--nx / --ny"
    if hmodel:
        options += " / --n-dir"
        per_point, what = base.n_dir * POINT_BYTES_PER_DIR, f" of {base.n_dir} orientations"
    else:
        per_point, what = STATE_BYTES, f" of {cfg.law().name}"
    opt.check_memory(npts * (per_point + POINT_BYTES), f"{npts:.3g} quadrature points{what}",
                     options, f"fewer cells{' or orientations' if hmodel else ''} ({options})")


def _warm_specimen(params=None):
    """Compile the specimen's kernels on tiny cases: the material field's update through its
    law (the H-model's flag counts and update kernel, both drivers, on 70 and 4 points of 8
    orientations; ``params``: another law's record, which has none), the stiffness on one
    element."""
    from hmodel import HParams
    from .adapter import MaterialField
    from .mesh import rectangle
    from .problem import Biaxial
    p = HParams(n_dir=8) if params is None or isinstance(params, HParams) else params
    for n in (70, 4):
        mf = MaterialField(n, [(p, np.arange(n))])
        t = mf.trial(np.zeros((2, 2, n)))
        mf.pattern_changes(t, t)
    Biaxial(rectangle(1.0, 1.0, 1, 1), p).stiffness(t.D)       # 1 quad: the 4 points of t


def _warm_indicators(params=None):
    """Compile fem's own kernels on tiny cases: the specimen's (``_warm_specimen`` of
    ``params``' law, default the H-model), the local indicators on one elastic point, the
    global check's banded kernels on 2 x 4 elements and the permutation parity of its fallback
    (det K by LU when K_d is singular: without it that kernel stayed uncompiled and every run
    announced a compilation)."""
    from hmodel import HParams
    from .indicators import GlobalCheck, local_indicators, permutation_parity
    from .mesh import rectangle
    from .problem import Biaxial
    I = np.eye(2)
    D = (np.einsum("ij,kl->ijkl", I, I) + np.einsum("ik,jl->ijkl", I, I)
         + np.einsum("il,jk->ijkl", I, I))[..., None] * 1e6
    local_indicators(D, n_sphere=8)
    permutation_parity(np.arange(2))
    _warm_specimen(params)
    p = HParams(n_dir=8) if params is None or isinstance(params, HParams) else params
    b = Biaxial(rectangle(1.0, 2.0, 2, 4), p)
    GlobalCheck(b)(b.stiffness(D[..., [0] * b.npts]))


def _fem_kernels(indicators: bool = True):
    """fem's Numba kernels: the adapter's and the problem's, and with ``indicators`` the
    bifurcation checks' (which ``fem burst`` does not use)."""
    import numba

    from . import adapter, indicators as ind, problem
    mods = (ind, adapter, problem) if indicators else (adapter, problem)
    return [v for m in mods for v in vars(m).values()
            if isinstance(v, numba.core.registry.CPUDispatcher)]


def main(argv=None) -> int:
    """``python -m fem biaxial|burst ...``: 0 done, 1 a step failed (converged steps kept), 2 bad
    option (one line, nothing written), 130 / 143 interrupted."""
    return opt.run_cli(build_parser(), argv, _run)


def read_any_params(path, option: str = "--params"):
    """The parameter record of the file ``path`` of any registered law (its "model" names the
    law; a file without it is the H-model's): ``point.params.load_params``, the one loader.
    ValueError of one line naming the file and the key."""
    from point.params import load_params
    return load_params(path, option)


def _specimen_config(args) -> BiaxialConfig:
    """The specimen of a command: its options, the material from --params FILE of any law (or
    Table I) with the options given on top (the H-model's: ``hmodel.params.params_from``;
    another law's: --sigma2 alone, its H-model options refused in one line); sets
    args.params_note."""
    from common.paramfile import override
    from point.contract import ParamError, material_of
    path = getattr(args, "params", None)
    base = read_any_params(path) if path else None
    kw = {k: v for k, v in vars(args).items()
          if k in BiaxialConfig.__dataclass_fields__ and k not in MATERIAL}
    if kw["imperfection"] == "none":
        kw["imperfection"] = None
    if base is None or isinstance(base, hp.HParams):
        for option, name in HMODEL_ONLY:
            if kw[name] is NOT_GIVEN:
                kw[name] = BiaxialConfig.__dataclass_fields__[name].default
        return BiaxialConfig(**kw).with_params(hp.params_from(args, base=base))
    law = material_of(base)
    given = [o for o, n in hp.PARAM_OPTIONS + HMODEL_ONLY
             if getattr(args, n, None) is not None and getattr(args, n) is not NOT_GIVEN]
    if given:
        fields = ", ".join(f for f in base.__dataclass_fields__ if not f.startswith("_"))
        raise opt.OptionError(f"{given[0]} is an option of the H-model: --params {path} is a "
                              f"{law.name} file (its fields {fields}; --sigma2 sets p0, "
                              "--imp-values the weak zone's)")
    for option, name in HMODEL_ONLY:
        kw[name] = None
    s2 = getattr(args, "sigma2", None)
    extra = [("--sigma2", "p0", float(s2))] if isinstance(s2, (int, float)) else []
    try:
        P, args.params_note = override(base, extra, f"the file {path}", base.replace)
    except ParamError as e:
        raise opt.OptionError(f"--sigma2 {e.value!r} is out of range: allowed {e.allowed}") from None
    return BiaxialConfig(**kw).with_params(P)


def _run(args, stage) -> int:
    if args.cmd == "burst":
        return _run_burst(args, stage)
    cfg = _specimen_config(args)
    check_config(cfg)
    opt.check_out_dir(args.out)
    P = cfg.params()
    compile_kernels(extra=_fem_kernels(), warm=lambda: _warm_indicators(P),
                    material=cfg.law())

    def progress(line):
        if line.startswith("step") and not stage.written:
            # row 0 is on disk: from now on every converged step is, and the line names the
            # last one as curve.csv has it (a step's line comes once the next one has converged)
            stage.wrote("curve.csv, fields.xdmf and newton.log up to the last converged step")
            stage.at(lambda: _step_under_way(os.path.join(args.out, "curve.csv")))
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)

    stage.at("set-up of the specimen")
    try:
        res = run_biaxial(cfg, args.out, progress=progress, params_note=args.params_note)
    except RuntimeError as e:
        print(f"error: {e}", file=sys.stderr)
        r = getattr(e, "result", None)
        if r is not None:
            print(f"{r.timings['steps']} converged steps are in {args.out}", file=sys.stderr)
            print(f"material: {r.summary['material']['name']}")
            print(format_summary(r.summary))
        return 1
    print(args.params_note)
    print(f"material: {res.summary['material']['name']}")
    print(format_summary(res.summary))
    end = res.summary.get("end")
    print(f"outcome: {end['line'] if end else 'complete'}")
    if end:
        print(f"the run ends there (every converged row written); {end['burst']}")
    t = res.timings
    print(f"{t['steps']} steps, {t['iterations']} Newton iterations, {t['total']:.1f} s total "
          f"(update {t['update']:.1f} s, assembly {t['assembly']:.1f} s, solve {t['solve']:.1f} s, "
          f"indicators + output {t['indicators_output']:.1f} s); outputs in {args.out}")
    return 0


def _step_under_way(curve_csv) -> str:
    """'load step 93, after step 92 (eps1 = 0.9200 %), the last row of curve.csv', read from the
    file when an interrupted run has closed it."""
    from .output import read_curve
    try:
        c = read_curve(curve_csv)
        k = int(c["step"][-1])
    except (OSError, ValueError, KeyError, IndexError):
        return "the load steps"
    return (f"load step {k + 1}, after step {k} (eps1 = {100 * c['eps1'][-1]:.4f} %), the last "
            "row of curve.csv")


def _run_burst(args, stage) -> int:
    """``python -m fem burst``: every option checked (one line, exit 2, nothing written), the
    kernels compiled, then ``run_burst`` with progress on stderr and the table of the runs on
    stdout."""
    spec = dataclasses.replace(_specimen_config(args), fields=args.fields)
    cfg = BurstConfig(specimen=spec, ratios=tuple(args.ratios),
                      start_fractions=tuple(args.start_fractions), dc=args.dc,
                      density=args.density, damping_ratio=args.damping_ratio,
                      steps_per_period=args.steps_per_period, path_strain=args.path_strain,
                      path_d_eps1=args.path_d_eps1, fields=args.fields)
    cfg.validate()
    check_config(spec)
    opt.check_out_dir(args.out)
    P = spec.params()
    compile_kernels(extra=_fem_kernels(indicators=False), warm=lambda: _warm_specimen(P),
                    material=spec.law())

    def progress(line):
        if not stage.written and line.startswith("drained path: start"):
            stage.wrote("paths.csv, history.csv and burst.csv up to the last finished row")
        stage.at(line.split(":")[0])
        if not args.quiet:
            print(line, file=sys.stderr, flush=True)

    stage.at("set-up of the specimen")
    os.makedirs(args.out, exist_ok=True)
    stage.wrote(record_params(args.out, spec.params(), f"python -m fem burst; {args.params_note}"))
    try:
        res = run_burst(cfg, args.out, progress=progress)
    except RuntimeError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    print(args.params_note)
    print(f"material: {res.summary['material']['name']}")
    print(format_burst(res.rows))
    cf = res.summary["closed_forms"]
    if isinstance(cf, str):
        print(f"closed forms: {cf}")
    for e in cf if isinstance(cf, list) else ():
        c, h = e["c_peak"], e["eta_peak_c"]
        print(f"R = {e['ratio']:g}, f = {e['start_fraction']:g}: c peak closed form (h = h_R) "
              f"{c['closed_form'] / 1e3:.4f} kPa at eta {h['closed_form']:.5f}; the FE's "
              + (f"{c['value'] / 1e3:.4f} kPa at {h['value']:.5f} (difference "
                 f"{c['difference']:+.3g} Pa, eta {h['difference']:+.2e})"
                 if c["value"] is not None else "does not peak"))
    t = res.summary["timings"]
    print(f"{len(res.rows)} runs, {t['total']:.1f} s total (drained path {t['drained']:.1f} s, "
          f"proportional paths {t['paths']:.1f} s, material point {t['material_point']:.1f} s, "
          f"dynamics {t['dynamics']:.1f} s, figures {t.get('figures', 0.0):.1f} s); outputs in "
          f"{args.out}")
    return 0


def format_burst(rows) -> str:
    """The table of the runs: the c peak (FE, material point), the switch, the outcome and the
    growth measure (``hmodel.burst_rule.energy_release``: the largest (E_c - E_c(0)) / W2_ext
    and the time it passed RELEASE x W2_ext, 'never' when it did not), the energy check."""
    from common.io import fmt
    lines = ["    R      f  switch  eta_switch  c_switch [kPa]  c_peak FE / MP [kPa]  "
             "eta_peak FE / MP   outcome        max (E_c-E_c0)/W2_ext  t_release/T1  t_end/T1  "
             "energy check"]
    for r in rows:
        lines.append(f"{r['ratio']:5g} {r['start_fraction']:6g}  {r['switch']:6s}  "
                     f"{r['eta_switch']:10.4f}  {r['c_switch'] / 1e3:14.3f}  "
                     f"{r['c_peak'] / 1e3:9.3f} / {r['mp_c_peak'] / 1e3:9.3f}  "
                     f"{r['eta_peak_c']:7.4f} / {r['mp_eta_peak_c']:7.4f}  {r['outcome']:13s}  "
                     f"{fmt(r['ke_w2ext_max'], '21.3g')}  {fmt(r['t_release_t1'], '12.2f', 'never')}"
                     f"  {r['t_end'] / r['t1']:8.1f}  {r['energy_check']:.1e}")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
