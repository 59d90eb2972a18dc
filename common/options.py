"""What the point, hmodel, fem and dem command lines (and the cross-check's) share: one
vocabulary of options, one-line errors, checked option types, output folders and memory checked
before any computation, Ctrl-C / SIGTERM as one line. The options of a law's parameters
(--params FILE with the options on top, docs/parameters.md) are the material point's:
``point.params`` (``add_param_options``, ``params_from``, ``record_params``; ``hmodel.params``
the H-model's), dem's ``dem.params``.

The vocabulary (``VOCABULARY``, issue 32) is written once: every option of the parts, by
name, with the quantity it is (in the paper's symbols), its unit, its kind and the range the
parser checks, the record fields that check it where a command binds it to its record
(``HParams``, ``DPParams``, ``DemParams``, ``BurstOptions``, ``ProbeOptions``, ``CalibrationOptions``,
``BiaxialConfig``, ``BurstConfig``, ``Specimen``, ``Dynamics``: their validation gives the range,
once, and the library's entry point calls the same validation; the command names the option with
``record_error``), and its former names (refused with "did you mean" the new one). The parsers
are built from it (``add``), so that every help says what the value is, its unit and its
default.

The rule of --out: required by every command that writes (a folder; the file of ``params``):
a newcomer sees where a run goes, and no two commands share a default folder. The folder
records the command that wrote it (command.json, ``mark_owner``); another command refuses it
before writing anything (``check_owner``, exit 2) unless --force.

The rule (both CLIs): every option is validated before anything is computed or written; a bad
one gives one line ``error: ...`` naming the option and its allowed range on stderr and exit
code 2, no traceback, nothing written. An interrupted run prints one line saying where it
stopped and exits 130 (Ctrl-C) or 143 (SIGTERM); outputs already written stay complete (every
file is written atomically or row by row).
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import numbers
import os
import re
import signal
import sys
import tempfile
import threading
from contextlib import contextmanager
from typing import NamedTuple

__all__ = ["OptionError", "Parser", "real", "integer", "reals", "add_quiet", "check_out_dir", "check_out_file",
           "Term", "VOCABULARY", "add", "add_out", "option_of", "record_error", "renamed_to",
           "Range", "term_of", "vocabulary_range",
           "check_owner", "mark_owner", "folder_owner", "check_file", "check_folder", "check_csv",
           "check_memory", "param_option_error", "add_param_options", "params_from", "record_params",
           "Stage", "run_cli", "COMPILE_NOTICE", "announce_compilation", "listen_for_compilation"]


class OptionError(ValueError):
    """A command-line option out of range (the message names the option)."""


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: raises OptionError instead of printing the usage and
    exiting (``run_cli`` prints it as ``error: ...`` and returns 2). A value that starts with a
    minus sign and a digit, a point, inf or nan (``--ratios -2,-1``, ``--dc -1e-3``, ``--ratios
    -inf``) is a value, not an option (argparse takes only plain negative numbers so), so that
    its type can check it and say what is allowed.

    Options are exact: no prefix matching (argparse would take ``--sigma`` for ``--sigma2`` and
    run), for this parser and its subcommands (``add_subparsers`` makes them of this class). An
    unknown option is refused by the subcommand that got it, naming the options it resembles and
    pointing at that subcommand's own ``--help``."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\.?\d|inf|nan)[\w.,+-]*$", re.IGNORECASE)

    def error(self, message):
        raise OptionError(f"{_reword(message, self)} (see {self.prog} --help)")

    def parse_known_args(self, args=None, namespace=None):
        """argparse's, but anything left over is an error here, in the (sub)parser that got it
        (argparse would hand it to the top parser, whose message names the top --help)."""
        ns, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(self._unknown(extras, ns))
        return ns, extras

    def _unknown(self, extras, ns) -> str:
        """The message for the first of ``extras``: an unknown option (with the options of this
        parser it resembles: those it abbreviates, else close spellings), an option of the
        subcommand written before it, or a stray value."""
        word = extras[0]
        if not word.startswith("-"):
            return f"unexpected argument {word!r} (an option is written --name value)"
        option = word.split("=", 1)[0]
        for sub in (a for a in self._actions if isinstance(a, argparse._SubParsersAction)):
            chosen = sub.choices.get(getattr(ns, sub.dest, None) or "")
            if chosen is not None and option in chosen._option_string_actions:
                return (f"{option} is an option of the subcommand: write it after "
                        f"'{chosen.prog.split()[-1]}'")
        return f"no option {option}" + _resembles(option, self._option_string_actions,
                                                  renamed_to(option, self.prog))


def _resembles(option, options, renamed=()) -> str:
    """' (options are written in full): did you mean --sigma2?' for ``option``: the ``options``
    it abbreviates (what argparse's prefix matching would have taken), else close spellings;
    ' (renamed --sigma2): did you mean --sigma2?' for a former name (``renamed``: its new names
    in this command, first)."""
    import difflib
    longs = sorted(o for o in options if o.startswith("--"))
    like = [o for o in longs if o.startswith(option)]
    if not like and not renamed:
        like = difflib.get_close_matches(option, longs, n=3, cutoff=0.75)
    like = list(renamed) + [o for o in like if o not in renamed]
    if not like:
        return ""
    why = f"renamed {' / '.join(renamed)}" if renamed else "options are written in full"
    return f" ({why}): did you mean {' or '.join(like)}?"


def _reword(message, parser) -> str:
    """argparse's message, reworded where it is unclear to a newcomer: an unknown subcommand or
    choice gets "did you mean" (``dem brust``: burst), a missing subcommand lists them."""
    import difflib
    m = re.match(r"argument (\S+): invalid choice: '?([^' ]*)'? \(choose from (.*)\)$", message)
    if m:
        what, word = m.group(1), m.group(2)
        choices = (re.findall(r"'([^']*)'", m.group(3))
                   or [c.strip() for c in m.group(3).split(",")])
        like = difflib.get_close_matches(word, choices, n=2, cutoff=0.6)
        guess = f"did you mean {' or '.join(like)}? " if like else ""
        if what.startswith("-"):
            return f"{what} {word!r}: {guess}allowed one of {', '.join(choices)}"
        return f"no command {word!r}: {guess}allowed one of {', '.join(choices)}"
    for sub in (a for a in parser._actions if isinstance(a, argparse._SubParsersAction)):
        if message in (f"the following arguments are required: {sub.dest}",
                       f"the following arguments are required: {sub.metavar}"):
            return f"a command is required: one of {', '.join(sub.choices)}"
    return message


def _interval(lo, hi, lo_open, hi_open):
    """'value > 0', 'value <= 1', '0 < value <= 360' (None: no bound)."""
    lt = lambda is_open: "<" if is_open else "<="
    if hi is None:
        return f"value {'>' if lo_open else '>='} {lo:g}" if lo is not None else "value"
    if lo is None:
        return f"value {lt(hi_open)} {hi:g}"
    return f"{lo:g} {lt(lo_open)} value {lt(hi_open)} {hi:g}"


def real(lo=None, hi=None, *, lo_open=True, hi_open=True, unit=""):
    """argparse type: a finite float in the interval (lo, hi) (open or closed ends; None: no
    bound), e.g. ``type=real(0, 360, hi_open=False, unit="deg")``."""
    allowed = f"allowed a finite {_interval(lo, hi, lo_open, hi_open)}" + (f" [{unit}]" if unit else "")

    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number: {allowed}") from None
        ok = math.isfinite(v)
        if ok and lo is not None:
            ok = v > lo if lo_open else v >= lo
        if ok and hi is not None:
            ok = v < hi if hi_open else v <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f"{text} is out of range: {allowed}")
        return v

    parse.__name__ = "real"
    return parse


def integer(lo=1, hi=None):
    """argparse type: an integer lo <= value (<= hi)."""
    allowed = f"allowed an integer {_interval(lo, hi, False, False)}"

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer: {allowed}") from None
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{text} is out of range: {allowed}")
        return v

    parse.__name__ = "integer"
    return parse


def argtype(parse, name=None):
    """argparse type from a parser raising ValueError (whose message says what is allowed):
    argparse then prints that message after the option's name."""
    def typed(text):
        try:
            return parse(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    typed.__name__ = name or parse.__name__
    return typed


def reals(lo=None, hi=None, *, lo_open=True, hi_open=True, unit=""):
    """argparse type: one or more comma-separated ``real`` values, as a list."""
    one = real(lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)

    def parse(text):
        vals = [one(x) for x in text.split(",") if x.strip()]
        if not vals:
            raise argparse.ArgumentTypeError(f"{text!r}: expected one or more comma-separated numbers")
        return vals

    parse.__name__ = "reals"
    return parse


def add_quiet(ap: argparse.ArgumentParser):
    """--quiet, the same on every command that shows progress: no progress lines on stderr
    (results, warnings and errors are still printed)."""
    add(ap, "--quiet")


# -- the vocabulary: one name per quantity, in the paper's symbols, for the three command lines --
@dataclasses.dataclass(frozen=True)
class Term:
    """One option of the vocabulary: ``name`` ("--sigma2"), ``help`` (what the value is: the
    quantity, in the paper's symbols), ``unit`` (SI; "-" dimensionless or a count; None: not a
    quantity, e.g. a file, a folder, a switch, a choice, a seed), ``kind`` ("real", "reals"
    (comma-separated), "int", "flag" (a switch, off unless given), "bool" (--x / --no-x),
    "path", "text", "choice"), the range (lo, hi, lo_open, hi_open; None: no bound) the parser
    checks where no record does (and a record whose field is listed in ``fields`` reads, where
    the term has one: ``vocabulary_range``, so that the two cannot differ), ``fields`` (the
    record fields that check it where a command binds the option to its record: "HParams.p0";
    or a function's argument that reads the range: "hmodel.run_burst.dc")
    and ``old`` (former names: (name, commands), commands as "dem biaxial", () for every command
    that has this option)."""

    name: str
    help: str
    unit: str | None = None
    kind: str = "real"
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = True
    hi_open: bool = True
    fields: tuple = ()
    old: tuple = ()

    @property
    def bounded(self) -> bool:
        return self.lo is not None or self.hi is not None

    def range_text(self) -> str:
        return _interval(self.lo, self.hi, self.lo_open, self.hi_open)


_T = Term
# Every option of python -m point, hmodel, fem and dem, once (the parsers are built from it:
# ``add``).
VOCABULARY = {t.name: t for t in (
    # -- where a command reads and writes, how it runs ----------------------------------------
    _T("--out", "where the command writes", None, "path"),
    _T("--force", "write into a folder another command wrote (its files of the same names are "
       "replaced)", None, "flag"),
    _T("--params", "parameter file (JSON; docs/parameters.md)", None, "path"),
    _T("--quiet", "no progress lines on stderr (results, warnings and errors still shown)", None,
       "flag"),
    _T("--resume", "keep the work already in --out and do the rest", None, "flag"),
    _T("--workers", "local worker processes", "-", "int", 1, 1024, False, False),
    _T("--threads", "threads of a run (results do not depend on it)", "-", "int", 1, None,
       False, fields=("threads.check_threads",)),
    _T("--scheduler", "dask.distributed scheduler address (host:port): the runs go to its "
       "workers", None, "text"),
    _T("--state", "DEM state file: an .npz written by python -m dem biaxial (stateA.npz, "
       "states/state_f*.npz)", None, "path"),
    _T("--biaxial", "output folder of python -m dem biaxial (its states/)", None, "path"),
    _T("--states", "comma-separated states of --biaxial (file names or targets of "
       "states/states.csv, e.g. f=0.9,f=0.95)", None, "text"),
    _T("--data", "CSV with a header row: columns eps1 [-] and q [Pa] (and eps_v or eps2 [-], s2 "
       "or sigma2 [Pa] where present), compression positive", None, "path"),
    _T("--mesh-file", "meshio-readable triangle or quad mesh (overrides --nx, --ny, --mesh)",
       None, "path"),
    _T("--cache", "folder of the cached dense samples", None, "path"),
    _T("--dem-params", "DemParams file of the DEM sample (python -m dem params)", None, "path"),
    _T("--hmodel-params", "HParams file of the H-model and FE parts (python -m hmodel params)",
       None, "path"),
    # -- the H-model's parameters (Table I): checked by HParams ----------------------------------
    _T("--kn", "normal contact stiffness kn", "N/m", fields=("HParams.kn",)),
    _T("--kt", "tangential contact stiffness kt", "N/m", fields=("HParams.kt",)),
    _T("--phi-g", "grain (contact) friction angle phi_g, mu = tan(phi_g)", "deg",
       fields=("HParams.phi_g", "DemParams.phi_g"), old=(("--friction", ()),)),
    _T("--r-g", "grain radius r_g", "m", fields=("HParams.r_g",)),
    _T("--alpha0", "initial opening angle alpha0 of the hexagons", "deg",
       fields=("HParams.alpha0",)),
    _T("--n-dir", "number of hexagon orientations", "-", "int", fields=("HParams.n_dir",)),
    _T("--thickness", "out-of-plane thickness h of the slab (file: null for 2 r_g)", "m",
       fields=("HParams.thickness",)),
    _T("--fabric-a", "fabric anisotropy a of omega(theta) = (1 + a cos 2(theta - b)) / n_dir",
       "-", fields=("HParams.fabric_a",)),
    _T("--fabric-b", "fabric direction b", "deg", fields=("HParams.fabric_b",)),
    # -- the material point of any law (python -m point) -----------------------------------------
    _T("--model", "constitutive law of the material point (a parameter file's \"model\")", None,
       "choice"),
    _T("--check-tangent", "before the run, the law's tangent against central differences of its "
       "own stress at the isotropic state and at a loaded state: refused if they disagree", None,
       "flag"),
    # -- non-associated Drucker-Prager's parameters (point.drucker_prager): checked by DPParams --
    _T("--shear-modulus", "shear modulus G of the isotropic elasticity", "Pa",
       fields=("DPParams.G",)),
    _T("--nu", "Poisson's ratio nu of plane strain (plane bulk modulus G / (1 - 2 nu))", "-",
       fields=("DPParams.nu",)),
    _T("--mu0", "mobilized friction mu0 = tau/p at the first yield", "-",
       fields=("DPParams.mu0",)),
    _T("--mu-p", "peak mobilized friction mu_p", "-", fields=("DPParams.mu_p",)),
    _T("--kappa-p", "plastic shear strain kappa_p at the peak of the friction", "-",
       fields=("DPParams.kappa_p",)),
    _T("--mu-c", "characteristic friction mu_c of the dilatancy rule beta = mu - mu_c "
       "(contraction below it, dilation above)", "-", fields=("DPParams.mu_c",)),
    # -- the DEM's parameters (the paper's set): checked by DemParams ----------------------------
    _T("--n", "number of disks", "-", "int", 1, 10_000_000, False, False,
       fields=("DemParams.n",)),
    _T("--seed", "seed of the random generator", None, "int", 0, None, False,
       fields=("DemParams.seed",)),
    _T("--r-min", "smallest disk radius", "m", fields=("DemParams.r_min",)),
    _T("--r-max", "largest disk radius", "m", fields=("DemParams.r_max",)),
    _T("--density", "mass density", "kg/m^3",
       fields=("DemParams.density", "Specimen.density", "BurstConfig.density")),
    _T("--kn-over-d", "normal contact stiffness over the mean diameter, kn/D", "Pa",
       fields=("DemParams.kn_over_d",)),
    _T("--kt-over-kn", "tangential over normal contact stiffness, kt/kn", "-",
       fields=("DemParams.kt_over_kn",)),
    _T("--damping", "Cundall (non-viscous) damping coefficient", "-",
       fields=("DemParams.damping",)),
    _T("--dt-safety", "time step over sqrt(m_min / kn)", "-", fields=("DemParams.dt_safety",)),
    _T("--rolling-friction", "rolling resistance mu_r: the rolling moment of a contact capped at "
       "mu_r R* fn (0: free rotation, the paper's)", "-", fields=("DemParams.rolling_friction",)),
    _T("--rolling-stiffness", "rolling stiffness k_r over kt R*^2 (used with --rolling-friction "
       "> 0)", "-", fields=("DemParams.rolling_stiffness",)),
    _T("--allow-soft", "run a DEM set outside the granular regime anyway (stiffness number "
       "kn/(sigma2 t) below 100: overlaps beyond 0.01 of the diameter; dem.regime), where it is "
       "refused otherwise; a summary records it", None, "flag"),
    # -- the loading ---------------------------------------------------------------------------
    _T("--sigma2", "confining (lateral) stress sigma2, the isotropic start's p0", "Pa", "real",
       0, 1e9, hi_open=False,
       fields=("HParams.p0", "DPParams.p0", "CalibrationOptions.confining"),
       old=(("--confining", ()),)),
    _T("--eps1-max", "axial strain eps1 where the drained test ends", "-", "real", 0, 0.5,
       fields=("BiaxialConfig.eps1_max", "CalibrationOptions.eps_max"), old=(("--eps-max", ()),)),
    _T("--d-eps1", "axial strain step of the drained path", "-", "real", 0, 0.05,
       fields=("BiaxialConfig.d_eps1",)),
    _T("--d-eps1-search", "axial strain step of the drained path during the search", "-",
       "real", 0, 0.05),
    _T("--eta-a", "stress ratio eta = q/p of point A (p = (s1 + s2)/2)", "-", "real", 0, 2,
       old=(("--eta", ()),)),
    _T("--rate", "axial strain rate", "1/s", "real", 0, 10, hi_open=False,
       fields=("BurstOptions.rate", "CalibrationOptions.rate")),
    _T("--compaction-phi-g", "grain friction angle phi_g during the compaction", "deg", "real",
       0, 90, lo_open=False, old=(("--compaction-friction", ()),)),
    _T("--save-fractions", "comma-separated fractions of the drained peak eta: the first state "
       "at each is saved in --out/states (for dem domain, dem burst)", "-", "reals", 0, 1,
       hi_open=False),
    _T("--save-etas", "comma-separated eta: the first state at each is saved too", "-", "reals",
       0, 2),
    _T("--no-vtk", "no VTK files of the particles", None, "flag"),
    _T("--post-peak-strain", "a test stops this axial strain after its peak", "-", "real",
       fields=("CalibrationOptions.post_peak_strain",)),
    _T("--smooth", "axial strain window of the moving average of q for the peak (0: raw)", "-",
       "real", fields=("CalibrationOptions.smooth",)),
    # -- directional analyses --------------------------------------------------------------------
    _T("--n-probes", "number of strain probes (directions), uniform before any refinement", "-",
       "int", 8, None, False, old=(("--n", ("hmodel probes", "hmodel domain")),)),
    _T("--strain-norm", "norm |d eps| of a strain probe (a rate probe: small)", "-", "real", 0,
       1e-2, hi_open=False, old=(("--norm", ("hmodel probes",)),)),
    _T("--stress-norm", "norm |d sigma| of a stress probe", "Pa", "real", 0, 1e8,
       fields=("ProbeOptions.norm",),
       old=(("--norm", ("dem probes", "dem domain")), ("--sigma-norm", ("hmodel probes",)))),
    _T("--stress-step", "spacing of the stress probes' directions alpha_sigma", "deg", "real",
       0, 360, hi_open=False),
    _T("--step-q3", "spacing of the probe directions alpha_sigma in the third quadrant", "deg",
       "real", 0, 90, hi_open=False),
    _T("--step-other", "spacing of the probe directions alpha_sigma elsewhere", "deg", "real",
       0, 90, hi_open=False),
    _T("--directions", "comma-separated probe directions alpha_sigma, in place of --step-q3 and "
       "--step-other", "deg", "reals", 0, 360, lo_open=False),
    _T("--ramp-steps", "length of a probe's stress ramp", "steps", "int",
       fields=("ProbeOptions.ramp_steps",)),
    _T("--max-steps", "cap of a run: undecided when reached", "steps", "int", 1, None, False,
       fields=("ProbeOptions.max_steps", "BurstOptions.max_steps",
                                         "SettleRule.max_steps")),
    _T("--runaway-ratio", "failure: |d eps|/|d eps_elastic| beyond this with the wall stresses "
       "lost", "-", fields=("ProbeOptions.runaway_ratio",)),
    _T("--fail-ratio", "failure: |d eps|/|d eps_elastic| beyond this", "-",
       fields=("ProbeOptions.fail_ratio",)),
    _T("--plastic-tol", "a probe is plastic if |d eps_p| > this |d eps_elastic|", "-",
       fields=("ProbeOptions.plastic_tol",)),
    _T("--relax-max-steps", "cap of a relaxation at fixed strain or stress", "steps", "int",
       fields=("ProbeOptions.relax_max_steps", "BurstOptions.relax_max_steps")),
    _T("--unbalanced-tol", "equilibrium: unbalanced-force ratio at every check of the window",
       "-", fields=("ProbeOptions.unbalanced_tol", "BurstOptions.unbalanced_tol")),
    _T("--stress-tol", "equilibrium: stress error at every check of the window (the wall "
       "stresses' from their targets; dem burst: |c - c_target|)", "Pa",
       fields=("ProbeOptions.stress_tol", "BurstOptions.stress_tol")),
    _T("--strain-tol", "equilibrium: strain drift over the window over the strain scale (a "
       "probe's |d eps|; dem burst: the larger of the strain since the switch and the elastic "
       "strain of 2.5 kPa)", "-", fields=("ProbeOptions.strain_tol", "BurstOptions.strain_tol")),
    _T("--ke-tol", "equilibrium: backbone kinetic energy per disk", "J",
       fields=("ProbeOptions.ke_tol", "BurstOptions.ke_tol")),
    _T("--window", "equilibrium window at 1000 disks (scaled with sqrt(n))", "steps", "int",
       fields=("ProbeOptions.window", "BurstOptions.window")),
    _T("--no-relax", "probe from the saved state as is (no stress-controlled relaxation)", None,
       "flag"),
    _T("--no-hmodel", "leave the H-model's boundary out of the figure", None, "flag"),
    # -- the burst experiment (docs/burst.md) ----------------------------------------------------
    _T("--ratios", "comma-separated R of the proportional strain paths d eps2 = R d eps1, each "
       "finite and < 0 (-1: isochoric)", "-", "reals", fields=("BurstConfig.ratios",),
       old=(("--burst-ratios", ("crosscheck",)),)),
    _T("--start-fractions", "comma-separated start states, fractions f of the drained peak eta",
       "-", "reals", 0, 1, hi_open=False, fields=("BurstConfig.start_fractions",
                                                 "hmodel.run_burst.start_fractions"),
       old=(("--burst-fractions", ("crosscheck",)),)),
    _T("--dc", "step of c = s1 + R s2 held after the switch (dG = B dc per unit thickness)",
       "Pa", "real", 0, None, False,
       fields=("BurstConfig.dc", "BurstOptions.dc", "hmodel.run_burst.dc")),
    _T("--path-strain", "largest axial strain of a proportional path from its start", "-",
       "real", 0, 0.5, fields=("BurstConfig.path_strain", "BurstOptions.path_strain",
                                "hmodel.run_burst.path_strain")),
    _T("--path-d-eps1", "axial strain step of the proportional paths", "-", "real", 0, 0.05,
       fields=("BurstConfig.path_d_eps1",)),
    _T("--width", "specimen width B", "m", "real", 0, None,
       fields=("Specimen.width", "BiaxialConfig.width")),
    _T("--height", "specimen height H", "m", "real", 0, None,
       fields=("Specimen.height", "BiaxialConfig.height")),
    _T("--damping-ratio", "damping ratio zeta of the lowest elastic mode (mass-proportional "
       "damping)", "-", "real", 0, 1, False, fields=("Dynamics.damping_ratio",
                                                       "BurstConfig.damping_ratio")),
    _T("--steps-per-period", "time steps in the lowest elastic period T1", "-", "int", 10, None,
       False, fields=("Dynamics.steps_per_period", "BurstConfig.steps_per_period")),
    _T("--no-cone", "no directional analysis (where each path's strain direction enters the "
       "cone W2 <= 0; the first W2 = 0 of the drained path)", None, "flag"),
    _T("--peak-drop", "c this far below its largest confirms the peak", "Pa",
       fields=("BurstOptions.peak_drop",)),
    _T("--peak-strain", "or the path this far beyond the largest c", "-",
       fields=("BurstOptions.peak_strain",)),
    _T("--below-rise", "below: from the first equilibrium of the staircase whose c reaches "
       "c_start + this (c_peak - c_start), all at rest", "-", fields=("BurstOptions.below_rise",)),
    _T("--hold", "how G is held after the switch: a dead load on the tied walls (one dynamic "
       "degree of freedom, no servo) or the servo on c", None, "choice",
       fields=("BurstOptions.hold",)),
    _T("--wall-mass", "the walls' generalized mass m_G under the dead load", "kg",
       fields=("BurstOptions.wall_mass",)),
    _T("--wall-period-steps", "the wall-mass rule: the walls' period on their contact stiffness",
       "steps", fields=("BurstOptions.wall_period_steps",)),
    _T("--stairs", "the staircase's first step of c is (loaded peak - c at rest) / this", "-",
       "int", fields=("BurstOptions.stairs",)),
    _T("--max-holds", "cap of the staircase's holds (the search then ends without a past run)",
       "-", "int", fields=("BurstOptions.max_holds",)),
    _T("--probe-d-eps1", "the kinematic probe at every equilibrium: axial strain moved along "
       "the path (docs/burst.md)", "-", fields=("BurstOptions.probe_d_eps1",)),
    _T("--probe-rate", "the kinematic probe's axial strain rate (at most --rate)", "1/s",
       fields=("BurstOptions.probe_rate",)),
    _T("--no-probes", "no kinematic probes (no k_path, no verdict of the theory)", None, "flag"),
    _T("--fail-strain", "failure: |d eps| since the switch beyond this", "-",
       fields=("BurstOptions.fail_strain",)),
    # -- the fit of the H-model --------------------------------------------------------------
    _T("--free", "comma-separated free parameters", None, "text"),
    _T("--bounds", "search ranges NAME=LO:HI,... (SI units, degrees)", None, "text"),
    _T("--starts", "starts of the search: the given values, then a seeded Latin hypercube", "-",
       "int", 1, None, False),
    _T("--w-epsv", "weight of eps_v against q, each scaled by its largest |value| (0: q only)",
       "-", "real", 0, None, False),
    _T("--max-nfev", "residual evaluations per start (a Jacobian costs 2 more paths per free "
       "parameter)", "-", "int", 1, None, False),
    # -- the FE specimen ---------------------------------------------------------------------
    _T("--nx", "cells across the width", "-", "int", fields=("BiaxialConfig.nx",)),
    _T("--ny", "cells along the height", "-", "int", fields=("BiaxialConfig.ny",)),
    _T("--mesh", "cell kind of the generated mesh", None, "choice",
       fields=("BiaxialConfig.mesh_kind",)),
    _T("--imperfection", "weak zone of the specimen", None, "choice",
       fields=("BiaxialConfig.imperfection",)),
    _T("--imp-size", "size of the weak zone over the width (spot radius, band half-width)",
       "-", fields=("BiaxialConfig.imp_size",)),
    _T("--imp-phi-g", "phi_g of the weak zone, or none", "deg", "text",
       fields=("BiaxialConfig.imp_phi_g",)),
    _T("--imp-alpha0", "alpha0 of the weak zone, or none", "deg", "text",
       fields=("BiaxialConfig.imp_alpha0",)),
    _T("--imp-angle", "angle of the weak band from the horizontal", "deg",
       fields=("BiaxialConfig.imp_angle",)),
    _T("--imp-values", "weak values of the material's parameters in the weak zone, "
       "FIELD=VALUE,... (the fields of --params FILE's law, SI units, degrees)", None, "text",
       fields=("BiaxialConfig.imp_values",)),
    _T("--rtol", "Newton: relative tolerance of the residual", "-",
       fields=("BiaxialConfig.rtol",)),
    _T("--max-iter", "Newton: iterations per load step at most", "-", "int",
       fields=("BiaxialConfig.max_iter",)),
    _T("--max-cutbacks", "Newton: halvings of a load step at most", "-", "int",
       fields=("BiaxialConfig.max_cutbacks",)),
    _T("--no-fields", "no fields.xdmf / fields.h5", None, "flag"),
    _T("--n-sphere", "strain directions sampled for the local minimum of W2", "-", "int",
       fields=("BiaxialConfig.n_sphere",)),
    # -- dem bench, calibrate; crosscheck ------------------------------------------------------
    _T("--steps", "time steps measured", "steps", "int", 1, None, False),
    _T("--rounds", "interleaved rounds of the measurement", "-", "int", 1, 100, False, False),
    _T("--busy-core", "measure beside a busy-loop process (a shared machine)", None, "flag"),
    _T("--target", "the curve to fit", None, "choice"),
    _T("--vary", "comma-separated DemParams fields (or their option names) to fit", None,
       "text"),
    _T("--seeds", "comma-separated samples (seeds) every set is run on; its figures are their "
       "means", None, "text"),
    _T("--check-seeds", "comma-separated samples (seeds) the best set is then run on, not among "
       "--seeds; the check's verdict is their mean", None, "text"),
    _T("--no-first-run-decision", "every set on every one of --seeds (by default a set whose "
       "first run misses a target by more than the sample's scatter lets the seeds' mean reach "
       "runs on no other seed)", None, "flag"),
    _T("--stop-decided-runs", "a set's first run stops as soon as its records decide a target "
       "missed (the secant once past its strain, peak q from below); the model takes its other "
       "figures as bounds or unknown and runs such a set on to its end where it lacks a figure",
       None, "flag"),
    _T("--initial", "sets of the space-filling (Sobol) design before the model proposes any (at "
       "least the varied parameters + 2)", "-", "int", fields=("CalibrationOptions.initial",)),
    _T("--batch", "sets the model proposes per round", "-", "int",
       fields=("CalibrationOptions.batch",)),
    _T("--max-evals", "parameter sets at most, the start set included, each run on its first "
       "seed and on the others unless that run decides it (may be raised on --resume)", "-", "int", fields=("CalibrationOptions.max_evals",)),
    _T("--full", "the paper's 12,000 disks at 0.01/s (see README for the time)", None, "flag"),
    _T("--no-dem", "H-model and FE only", None, "flag", old=(("--skip-dem", ()),)),
    _T("--no-domain", "no H-model bifurcation domain", None, "flag"),
    _T("--no-burst", "no burst section (proportional strain paths, c held below / past its "
       "peak, in the three parts: docs/burst.md)", None, "flag"),
    _T("--dem-domain", "directional analyses at every saved DEM state (the DEM's bifurcation "
       "domain)", None, "bool"),
)}


def renamed_to(option, prog) -> list:
    """The new names, in the vocabulary, of the former option name ``option`` in the command
    ``prog`` ("python -m dem biaxial")."""
    command = " ".join(str(prog).split()[2:]) if str(prog).startswith("python -m ") else str(prog)
    return [t.name for t in VOCABULARY.values() for old, cmds in t.old
            if old == option and t.name != option and (not cmds or command in cmds)]


def option_of(record: str, field: str) -> str:
    """The option of the record's field ("DemParams", "phi_g" -> "--phi-g"): the vocabulary's
    term that lists it, else --field-with-dashes."""
    key = f"{record}.{field}"
    for t in VOCABULARY.values():
        if key in t.fields:
            return t.name
    return "--" + field.replace("_", "-")


def record_error(e, record: str) -> "OptionError":
    """The OptionError of a record's ValueError ``e`` whose message starts with the field
    ("rate=0.0; allowed range: ...", "width = 0 is out of range ...", "HParams.kn = ..."), the
    field replaced by its option ("--rate 0.0; allowed range: ...")."""
    msg = str(e)
    m = re.match(r"^(?:\w+\.)?([a-z_][a-z0-9_]*)\s?=\s?(.*)$", msg)
    if m is None:
        return OptionError(msg)
    return OptionError(f"{option_of(record, m.group(1))} {m.group(2)}")


# -- a record's range of a field: its own, or the vocabulary's term of the field (issue 33) ------
class Range(NamedTuple):
    """The allowed values of a ``record``'s ``field``: an integer or a finite real in (lo, hi)
    (open or closed ends; None: no bound; a field's name: that field's value, checked before).
    A record writes its own ranges so, or reads them from the vocabulary (``vocabulary_range``)
    where the field's option is a term other commands share: the range is then written once, in
    the term. ``contains`` is the rule; ``text`` says it ("0 < value <= 10"), ``check`` refuses
    in one line naming the option ("--rate 0.0: allowed 0 < value <= 10 [1/s]")."""
    record: str                 # "CalibrationOptions"
    field: str
    kind: str                   # "int" or "real"
    lo: float | str | None
    hi: float | str | None
    lo_open: bool = True
    hi_open: bool = True
    unit: str = ""

    @property
    def option(self) -> str:
        return option_of(self.record, self.field)

    def _end(self, bound, rec):
        """(the bound's value, its text): a number, or another field's option (None: no
        bound)."""
        if bound is None:
            return None, None
        if isinstance(bound, str):
            return (None if rec is None else getattr(rec, bound)), option_of(self.record, bound)
        return bound, f"{bound:g}"

    def text(self, name="value", unit=False) -> str:
        """"1 <= value <= 64", "0 < value < --eps1-max" (as a help says it: no unit, no kind);
        ``name`` in place of "value" ("0 < rate <= 10"), ``unit``: with the unit ("[1/s]")."""
        lt = lambda is_open: "<" if is_open else "<="
        lo, hi = self._end(self.lo, None)[1], self._end(self.hi, None)[1]
        if self.hi is None:
            rng = (f"{name} {'>' if self.lo_open else '>='} {lo}" if self.lo is not None
                   else name)
        elif self.lo is None:
            rng = f"{name} {lt(self.hi_open)} {hi}"
        else:
            rng = f"{lo} {lt(self.lo_open)} {name} {lt(self.hi_open)} {hi}"
        if unit and self.unit not in ("", "-", None):
            rng += f" [{self.unit}]"
        return rng

    def contains(self, v, rec=None) -> bool:
        """True if ``v`` is allowed: of the kind (an integer; a finite real), not a bool, inside
        the ends (a bound that is another field: its value in ``rec``, unchecked without it)."""
        ok = (isinstance(v, numbers.Integral) if self.kind == "int" else
              isinstance(v, numbers.Real) and math.isfinite(v)) and not isinstance(v, bool)
        for bound, is_open, above in ((self.lo, self.lo_open, True),
                                      (self.hi, self.hi_open, False)):
            b = self._end(bound, rec)[0]
            if ok and b is not None:
                ok = ((v > b if is_open else v >= b) if above else
                      (v < b if is_open else v <= b))
        return bool(ok)

    def check(self, rec):
        """The value of the field in ``rec`` as an int or a float; OptionError otherwise, one
        line naming the option and what it allows."""
        v = getattr(rec, self.field)
        if not self.contains(v, rec):
            others = [b for b in (self.lo, self.hi) if isinstance(b, str)]
            given = "".join(f" ({option_of(self.record, b)} {getattr(rec, b)!r})"
                            for b in others)
            kind = "an integer " if self.kind == "int" else ""
            raise OptionError(f"{self.option} {v!r}{given}: allowed {kind}"
                              f"{self.text(unit=True)}")
        return int(v) if self.kind == "int" else float(v)


def term_of(record: str, field: str) -> Term:
    """The vocabulary's term whose ``fields`` list the record's field ("BurstOptions", "rate"
    -> the term of --rate); KeyError if none does (``option_of``'s guess of a name is no term of
    the field: BurstOptions.strain_norm is no --strain-norm)."""
    key = f"{record}.{field}"
    for t in VOCABULARY.values():
        if key in t.fields:
            return t
    raise KeyError(f"no term of the vocabulary lists {key}")


def vocabulary_range(record: str, field: str, **ends) -> Range:
    """The range of the vocabulary's term of the record's field (``term_of``: an option other
    commands share, its range written there), with the ends ``ends`` gives (lo, hi, lo_open,
    hi_open) in place of its own. Read at the call: a record that reads it in its validation
    follows the term."""
    t = term_of(record, field)
    r = dict(lo=t.lo, hi=t.hi, lo_open=t.lo_open, hi_open=t.hi_open)
    r.update(ends)
    return Range(record, field, "int" if t.kind == "int" else "real", unit=t.unit or "", **r)


def _default_text(term, default):
    if term.kind == "flag":
        return "off"
    if isinstance(default, (list, tuple)):
        return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in default)
    if isinstance(default, float):
        return f"{default:g}"
    return str(default)


def add(ap, name, default=None, *, note="", record=None, allowed=None, default_text=None,
        required=False, many=False, parse=None, choices=None, dest=None, metavar=None,
        flag_value=True):
    """Add the vocabulary's option ``name`` to the parser (or group) ``ap``, its help written
    from the term: what it is, [unit], the range the parser checks, the default (``default``,
    or ``default_text`` where the default is worked out later; required: "required").
    ``record``: the record whose validation checks the value (a field of it is among the term's
    ``fields``): the parser checks only the type, the command validates the record before any
    computation and names the option with ``record_error`` / ``param_option_error``;
    ``allowed``: the record's range as the help says it ("0 < value <= 10", from the record's
    own table, e.g. dem.calibrate's ``CalibrationOptions.allowed_text``), where the parser checks
    none.
    ``note``: what the value does in this command, after the term's text; ``many``: a
    comma-separated list of the term's kind; ``parse``: the text's parser (kind "text", or a
    list of checked values). ``flag_value``: False for a "--no-x" flag stored in ``dest``
    (True by default)."""
    t = VOCABULARY[name]
    if record is not None and not any(f.startswith(record + ".") for f in t.fields):
        raise KeyError(f"{name}: no field of {record} in the vocabulary's term")
    ranged = t.bounded and record is None
    lo, hi = (t.lo, t.hi) if ranged else (None, None)
    unit = t.unit if t.unit not in (None, "-") else ""
    kw = {}
    if t.kind in ("real", "reals"):
        one = real if t.kind == "real" and not many else reals
        kw["type"] = parse or one(lo, hi, lo_open=t.lo_open, hi_open=t.hi_open, unit=unit)
    elif t.kind == "int":
        kw["type"] = parse or integer(lo, hi)
    elif t.kind in ("text", "path", "choice"):
        if parse is not None:
            kw["type"] = parse
        if choices is not None:
            kw["choices"] = choices
    if t.kind == "flag":
        kw["action"] = "store_true" if flag_value else "store_false"
    elif t.kind == "bool":
        kw["action"] = argparse.BooleanOptionalAction
    if dest:
        kw["dest"] = dest
    if metavar:
        kw["metavar"] = metavar
    text = t.help + (f" [{t.unit}]" if t.unit else "") + (f"; {note}" if note else "")
    if ranged:
        text += f"; allowed {t.range_text()}"
    elif allowed and record is not None:
        text += f"; allowed {allowed}"
    if choices:
        text += f"; one of {', '.join(choices)}"
    if required:
        text += "; required"
    else:
        d = default_text if default_text is not None else _default_text(t, default)
        text += f"; default {d}"
    if t.kind == "flag":
        default = not flag_value
    return ap.add_argument(name, default=default, required=required,
                           help=text.replace("%", "%%"), **kw)


def add_out(ap, what="folder"):
    """--out, required everywhere (the rule: a command writes only where it is told, and the
    output folder records the command that wrote it); ``what`` "folder" (with --force) or
    "file" (the parameter file of ``params``)."""
    if what == "file":
        return add(ap, "--out", required=True, note="the parameter file (JSON) to write",
                   metavar="FILE")
    add(ap, "--out", required=True, metavar="DIR", note="a folder (created) that records the "
        "command that wrote it (command.json); another command's folder is refused unless "
        "--force")
    add(ap, "--force")


def check_out_dir(path, option="--out"):
    """Refuse an output folder that cannot be used, before any computation: an existing file,
    or a folder (or, if it does not exist yet, its nearest existing parent) where no file can be
    created. Nothing is left behind (the probe file is removed)."""
    p = os.path.abspath(os.fspath(path))
    if os.path.exists(p) and not os.path.isdir(p):
        raise OptionError(f"{option} {path}: is an existing file, not a folder: allowed a folder "
                          "(existing or to be created)")
    probe = p
    while not os.path.exists(probe):
        probe = os.path.dirname(probe)
    if not os.path.isdir(probe):
        raise OptionError(f"{option} {path}: {probe} is a file, so the folder cannot be created")
    try:
        with tempfile.TemporaryFile(dir=probe):
            pass
    except OSError as e:
        what = "folder" if probe == p else f"parent folder {probe}"
        raise OptionError(f"{option} {path}: the {what} is not writable ({e.strerror}): allowed a "
                          "writable folder") from None


def check_out_file(path, option="--out"):
    """Refuse an output file that cannot be written, before any computation: an existing folder,
    or a parent folder that is missing, a file or not writable. Nothing is left behind."""
    p = os.path.abspath(os.fspath(path))
    if os.path.isdir(p):
        raise OptionError(f"{option} {path}: is a folder: allowed a file (existing or to be created)")
    parent = os.path.dirname(p)
    if not os.path.isdir(parent):
        raise OptionError(f"{option} {path}: the folder {parent} does not exist: allowed a file "
                          "in an existing folder")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as e:
        raise OptionError(f"{option} {path}: the folder {parent} is not writable ({e.strerror}): "
                          "allowed a file in a writable folder") from None


def _available_bytes():
    """MemAvailable of /proc/meminfo [bytes] (physical pages available elsewhere), or None."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(nbytes, what, options, allowed="a smaller run"):
    """Refuse a run whose estimated memory ``nbytes`` exceeds the memory available now, naming
    the options that set it (``options``, e.g. "--eps1-max / --d-eps1"), the estimate and what
    is ``allowed`` instead."""
    avail = _available_bytes()
    if avail is not None and nbytes > avail:
        raise OptionError(f"{options}: {what} would need about {nbytes / 1e9:.3g} GB of memory, "
                          f"{avail / 1e9:.3g} GB available: allowed {allowed}")


class Stage:
    """Where a command is, for the line printed when it is interrupted: ``at(text)`` as it goes
    (or ``at(callable)``, asked only when the line is printed: e.g. the last row a file holds
    then), ``wrote(name)`` for every output file completed. A command that says nothing of its
    files gets them named all the same: the files of ``out_dir`` new or changed since
    ``run_cli`` started it (``before``, a ``snapshot``)."""

    def __init__(self, out_dir=None):
        self.where = "start-up"
        self.out_dir = out_dir
        self.written = []
        self.before = None

    def at(self, text):
        self.where = text

    def wrote(self, *names):
        self.written.extend(names)

    def changed(self) -> list:
        """The files of ``out_dir`` written since ``before`` (relative paths, sorted)."""
        if self.out_dir is None or self.before is None:
            return []
        now = snapshot(self.out_dir)
        return sorted(k for k, v in now.items() if self.before.get(k) != v)

    def line(self, signame):
        if self.written:
            done = f"complete in {self.out_dir}: {', '.join(self.written)}"
        else:
            new = _grouped(self.changed())
            shown = ", ".join(new[:12]) + (f" and {len(new) - 12} more" if len(new) > 12 else "")
            done = f"written so far in {self.out_dir}: {shown}" if new else "no output written yet"
        where = self.where() if callable(self.where) else self.where
        return f"interrupted ({signame}) during {where}; {done}"


def _grouped(paths) -> list:
    """The files of a folder as a line names them: its own files, then each sub-folder as
    "states/ (6 files)" (or its one file's path)."""
    top, sub = [], {}
    for p in paths:
        head, _, rest = p.partition(os.sep)
        if rest:
            sub.setdefault(head, []).append(p)
        else:
            top.append(p)
    return top + [v[0] if len(v) == 1 else f"{k}{os.sep} ({len(v)} files)"
                  for k, v in sorted(sub.items())]


# -- whose folder: every command that writes a folder records itself there -------------------
OWNER_FILE = "command.json"
_SNAPSHOT_MAX = 20_000      # files listed at most (a DEM folder holds a few thousand)
# commands that moved (issue 33): a folder the former one wrote is the new one's (its --resume)
RENAMED_COMMANDS = {"python -m dem crosscheck": "python -m crosscheck"}


def snapshot(path) -> dict:
    """Relative path -> (size, mtime_ns) of every file under ``path`` ({} if it is no folder)."""
    out = {}
    if not os.path.isdir(path):
        return out
    for root, _, files in os.walk(path):
        for f in files:
            full = os.path.join(root, f)
            try:
                st = os.stat(full)
            except OSError:
                continue
            out[os.path.relpath(full, path)] = (st.st_size, st.st_mtime_ns)
            if len(out) >= _SNAPSHOT_MAX:
                return out
    return out


def folder_owner(path):
    """The command that wrote the folder ``path`` ("python -m dem biaxial"): its command.json,
    else the note of its params.json (every command's starts with the command: folders written
    before command.json), else None (no record: a folder of no command, or empty). A command
    that moved is named as it is now (``RENAMED_COMMANDS``)."""
    import json
    try:
        with open(os.path.join(path, OWNER_FILE)) as f:
            c = json.load(f).get("command")
        if isinstance(c, str) and c:
            return RENAMED_COMMANDS.get(c, c)
    except (OSError, ValueError, AttributeError):
        pass
    try:
        with open(os.path.join(path, "params.json")) as f:
            note = json.load(f).get("note", "")
        m = re.match(r"(python -m (?:hmodel|point|fem|dem) [a-z]+)\b", note or "")
        if m:
            return m.group(1)
    except (OSError, ValueError, AttributeError, TypeError):
        pass
    return None


def check_owner(path, command, force=False, option="--out"):
    """Refuse, before anything is written, an output folder another command wrote (its
    command.json, or its params.json's note), unless ``force``."""
    owner = folder_owner(path) if os.path.isdir(path) else None
    if owner is not None and owner != command and not force:
        raise OptionError(f"{option} {path}: the output folder of {owner}, not of {command}: "
                          "allowed a new or empty folder, or one of this command (--force writes "
                          "into it all the same)")


def mark_owner(path, command, argv=None, before=None):
    """Record ``command`` in ``path``/command.json if the folder is its output (it wrote
    something since ``before``, a ``snapshot``) and the folder does not say so already (a
    forced run records the command it wrote over)."""
    import json
    import time as _time
    if not os.path.isdir(path):
        return
    owner = folder_owner(path)
    if owner == command and os.path.exists(os.path.join(path, OWNER_FILE)):
        return
    if before is not None and snapshot(path) == before:
        return          # nothing written (refused, or interrupted before any file)
    doc = {"command": command, "argv": list(argv) if argv is not None else None,
           "written": _time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    if owner is not None and owner != command:
        doc["written_over"] = owner
    from .io import atomic_write_bytes
    try:
        atomic_write_bytes(os.path.join(path, OWNER_FILE), (json.dumps(doc, indent=1) + "\n").encode())
    except OSError:
        pass


# -- file arguments: checked for what they should be, one line naming what was expected -------
def check_file(path, option, what):
    """``path`` must be an existing file: else an OptionError naming ``what`` it should be."""
    if os.path.isdir(path):
        raise OptionError(f"{option} {path}: is a folder: allowed {what}")
    if not os.path.exists(path):
        raise OptionError(f"{option} {path}: no such file: allowed {what}")


def check_folder(path, option, what, commands=()):
    """``path`` must be an existing folder (of one of ``commands``, where its command.json or
    params.json says whose it is): else an OptionError naming ``what`` it should be."""
    if os.path.isfile(path):
        raise OptionError(f"{option} {path}: is a file, not a folder: allowed {what}")
    if not os.path.isdir(path):
        raise OptionError(f"{option} {path}: no such folder: allowed {what}")
    owner = folder_owner(path)
    if commands and owner is not None and owner not in commands:
        raise OptionError(f"{option} {path}: the output folder of {owner}: allowed {what}")


def check_csv(path, columns, option, what=None):
    """``path`` must be a CSV file whose header row names every one of ``columns`` (a sequence:
    each a name, or a tuple of alternatives); an OptionError of one line naming what was
    expected otherwise (never the reader's own pages of messages)."""
    names = " and ".join(c if isinstance(c, str) else " or ".join(c) for c in columns)
    what = what or f"a CSV file with a header row naming {names}"
    check_file(path, option, what)
    try:
        with open(path, encoding="utf-8") as f:
            head = f.readline()
    except UnicodeDecodeError:
        raise OptionError(f"{option} {path}: not text: allowed {what}") from None
    except OSError as e:
        raise OptionError(f"{option} {path}: {(e.strerror or str(e)).lower()}: allowed {what}") from None
    have = [h.strip().strip('"') for h in head.strip().split(",")]
    missing = [c if isinstance(c, str) else " or ".join(c) for c in columns
               if not any(x in have for x in ((c,) if isinstance(c, str) else c))]
    if missing or len(have) < 2:
        shown = head.strip()[:60] + ("..." if len(head.strip()) > 60 else "")
        raise OptionError(f"{option} {path}: no column {', '.join(missing) or names} in its first "
                          f"line ({shown!r}): allowed {what}")


class Terminated(BaseException):
    """SIGTERM, raised in the main thread like KeyboardInterrupt for Ctrl-C."""


def _in_callback(frame) -> bool:
    """True if ``frame`` runs where an exception raised by a signal handler would not reach the
    run: inside a finaliser (a ``__del__`` method, a ``weakref.finalize`` callback: Python
    prints "Exception ignored in ..." and goes on, so the run would end as if never
    interrupted; llvmlite frees its objects in ``__del__`` all through Numba's first
    compilation), or inside Numba's unpickling callback (compiled code calls it from C to box
    every returned array, among others, and Numba's tuple boxing goes on past a failed element:
    an exception raised there comes out as ``SystemError: ... returned a result with an
    exception set`` instead of itself)."""
    import weakref
    codes = {weakref.finalize.__call__.__code__}
    if "numba.core.serialize" in sys.modules:
        from numba.core.serialize import _numba_unpickle
        codes.add(_numba_unpickle.__code__)
    while frame is not None:
        if frame.f_code in codes or frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def _send_again(signum):
    """The signal ``signum`` to the main thread again in 5 ms (a callback returns in
    microseconds, so its exception is then raised in the run's own code)."""
    again = threading.Timer(0.005, signal.pthread_kill, (threading.main_thread().ident, signum))
    again.daemon = True
    again.start()


def _interrupt_handler(exc_type):
    """A signal handler raising ``exc_type`` in the main thread, or, if the signal lands where
    the exception would be lost or mangled (``_in_callback``), sending the signal again 5 ms
    later (``_send_again``). The exception carries the signal (``signum``): where it is lost
    all the same, in a callback ``_in_callback`` does not know (any weakref callback, e.g. a
    WeakValueDictionary's, which the garbage collector calls from C), Python hands it to
    ``sys.unraisablehook``, and ``_unraisable_hook`` sends the signal again."""
    def handler(signum, frame):
        if _in_callback(frame):
            _send_again(signum)
            return
        e = exc_type()
        e.signum = signum
        raise e
    return handler


def _unraisable_hook(previous):
    """``sys.unraisablehook`` for the run: an exception of the interrupt handler that Python
    could not raise (it came inside a callback called from C: "Exception ignored in ...") is
    not printed but its signal sent again (``_send_again``), so the run still stops; anything
    else goes to ``previous``."""
    def hook(u):
        signum = getattr(u.exc_value, "signum", None)
        if isinstance(u.exc_value, (Terminated, KeyboardInterrupt)) and signum is not None:
            _send_again(signum)
            return
        previous(u)
    return hook


@contextmanager
def _sigterm_raises():
    """SIGTERM raises Terminated and SIGINT KeyboardInterrupt (unless SIGINT is ignored), never
    inside a finaliser or a callback of compiled code (see ``_in_callback``), and never lost in
    a callback called from C (``_unraisable_hook``)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {signal.SIGTERM: signal.signal(signal.SIGTERM, _interrupt_handler(Terminated))}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        old[signal.SIGINT] = signal.signal(signal.SIGINT, _interrupt_handler(KeyboardInterrupt))
    old_hook = sys.unraisablehook
    sys.unraisablehook = _unraisable_hook(old_hook)
    try:
        yield
    finally:
        sys.unraisablehook = old_hook
        for signum, handler in old.items():
            signal.signal(signum, handler)


def run_cli(parser, argv, run, errors=(ValueError,)) -> int:
    """Parse ``argv`` and call ``run(args, stage)`` -> exit code, with the rules of this module:
    a parse error or one of ``errors`` -> one line ``error: ...``, exit 2; Ctrl-C -> 130,
    SIGTERM -> 143, with ``stage.line(...)``."""
    stage = Stage()
    try:
        args = parser.parse_args(argv)
        command = command_of(parser, args)
        folder = writes_folder(parser, args)
        if folder:
            check_owner(args.out, command, getattr(args, "force", False))
    except OptionError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    stage.out_dir = getattr(args, "out", None)
    if folder:
        stage.before = snapshot(args.out)
    try:
        with _sigterm_raises():
            return run(args, stage)
    except errors as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(stage.line("Ctrl-C"), file=sys.stderr)
        return 130
    except Terminated:
        print(stage.line("SIGTERM"), file=sys.stderr)
        return 143
    finally:
        if folder:
            mark_owner(args.out, command, sys.argv[1:] if argv is None else argv, stage.before)


def _chosen(parser, args):
    """The subparser ``args`` were parsed by (``parser`` itself if it has no subcommands)."""
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            return a.choices.get(getattr(args, a.dest, None) or "", parser)
    return parser


def command_of(parser, args) -> str:
    """"python -m dem biaxial": the command ``args`` were parsed for."""
    return _chosen(parser, args).prog


def writes_folder(parser, args) -> bool:
    """True if the command writes an output folder (--out DIR, with --force)."""
    return ("--force" in _chosen(parser, args)._option_string_actions
            and getattr(args, "out", None) is not None)


# the line that announces a compilation of the kernels (CLI and library alike), with its time:
# 85-141 s for all of hmodel's on this machine, 10-25 s for fem's and dem's own
COMPILE_NOTICE = "compiling kernels, once: one to two minutes (Numba caches them for later runs)"
_compile_announced = False      # COMPILE_NOTICE printed in this process
_listening = False              # listen_for_compilation registered
_PACKAGES = ("hmodel", "fem", "dem")


def _announce(stream=None):
    global _compile_announced
    print(COMPILE_NOTICE, file=sys.stderr if stream is None else stream, flush=True)
    _compile_announced = True


def announce_compilation(functions, stream=None):
    """Print COMPILE_NOTICE ("compiling kernels, once: one to two minutes") if some Numba
    function of ``functions`` has no compiled code in this process and none in Numba's cache
    (the first run after an install); returns True if it printed. The first call then compiles
    and caches them (time the caller should keep out of its reported timings)."""
    for f in functions:
        if getattr(f, "signatures", None) or getattr(f, "targetoptions", {}).get("inline") == "always":
            continue      # compiled in this process, or inlined into its callers (never cached alone)
        try:      # Numba's on-disk index of this function: empty when missing or stale
            cached = bool(f._cache._cache_file._load_index())
        except Exception:
            cached = True     # unknown: say nothing rather than something wrong
        if not cached:
            _announce(stream)
            return True
    return False


def listen_for_compilation():
    """Print COMPILE_NOTICE on stderr the first time, in this process, that Numba compiles a
    function of hmodel, fem or dem (not when it loads one from its cache), unless the CLI's
    ``announce_compilation`` has said so already: a script's first library call after an
    install is then announced as the CLI's is. Registered once, by importing hmodel or dem."""
    from numba.core import event

    class FirstCompilation(event.Listener):
        def on_start(self, ev):
            f = getattr(ev.data.get("dispatcher"), "py_func", None)
            if (not _compile_announced
                    and (getattr(f, "__module__", None) or "").split(".")[0] in _PACKAGES):
                _announce()

        def on_end(self, ev):
            pass

    global _listening
    if not _listening:
        event.register("numba:compile", FirstCompilation())
        _listening = True
