"""What the hmodel and fem command lines share: one-line errors, checked option types, output
folders and memory checked before any computation, Ctrl-C / SIGTERM as one line, and the model
parameters of a command (``add_param_options``, ``params_from``, ``record_params``: --params FILE
with the options on top, docs/parameters.md).

The rule (both CLIs): every option is validated before anything is computed or written; a bad
one gives one line ``error: ...`` naming the option and its allowed range on stderr and exit
code 2, no traceback, nothing written. An interrupted run prints one line saying where it
stopped and exits 130 (Ctrl-C) or 143 (SIGTERM); outputs already written stay complete (every
file is written atomically or row by row).
"""
from __future__ import annotations

import argparse
import math
import os
import re
import signal
import sys
import tempfile
import threading
from contextlib import contextmanager

__all__ = ["OptionError", "Parser", "real", "integer", "reals", "add_quiet", "check_out_dir", "check_out_file",
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
        raise OptionError(f"{message} (see {self.prog} --help)")

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
        return f"no option {option}" + _resembles(option, self._option_string_actions)


def _resembles(option, options) -> str:
    """' (options are written in full): did you mean --sigma2?' for ``option``: the ``options``
    it abbreviates (what argparse's prefix matching would have taken), else close spellings."""
    import difflib
    longs = sorted(o for o in options if o.startswith("--"))
    like = ([o for o in longs if o.startswith(option)]
            or difflib.get_close_matches(option, longs, n=3, cutoff=0.75))
    if not like:
        return ""
    return f" (options are written in full): did you mean {' or '.join(like)}?"


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
    ap.add_argument("--quiet", action="store_true",
                    help="no progress lines on stderr (results, warnings and errors still shown)")


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


def param_option_error(e, option_of=None):
    """The OptionError of an HParams ``ParamError`` ``e``, naming the command-line option of the
    field (``--phi-g`` for phi_g, ``--sigma2`` for p0, or ``option_of[field]``)."""
    opts = {"p0": "--sigma2", **(option_of or {})}
    opt = opts.get(e.name, "--" + e.name.replace("_", "-"))
    return OptionError(f"{opt} {e.value!r} is out of range: allowed {e.allowed}")


# the options of the HParams fields (p0 is the confining stress of a test: --sigma2)
PARAM_OPTIONS = (("--kn", "kn", "normal contact stiffness [N/m]"),
                 ("--kt", "kt", "tangential contact stiffness [N/m]"),
                 ("--phi-g", "phi_g", "contact friction angle [deg]"),
                 ("--r-g", "r_g", "grain radius [m]"),
                 ("--alpha0", "alpha0", "initial hexagon opening angle [deg]"),
                 ("--n-dir", "n_dir", "number of hexagon orientations"),
                 ("--thickness", "thickness", "slab thickness h [m] (file: null for 2 r_g)"),
                 ("--fabric-a", "fabric_a", "fabric anisotropy a, |a| < 1"),
                 ("--fabric-b", "fabric_b", "fabric direction b [deg]"))


def add_param_options(ap: argparse.ArgumentParser):
    """--params FILE and an option for every HParams field but p0 (the commands' --sigma2), all
    None unless given: the file (or Table I) supplies the rest (``params_from``)."""
    g = ap.add_argument_group("model parameters (Table I unless --params FILE; an option given "
                              "overrides the file)")
    g.add_argument("--params", default=None, metavar="FILE",
                   help="HParams file (python -m hmodel params --out FILE; docs/parameters.md)")
    for option, name, text in PARAM_OPTIONS:
        g.add_argument(option, type=int if name == "n_dir" else float, default=None, help=text)


def params_from(args, p0=None):
    """The HParams of a command: the --params file (or Table I), then the options given on top;
    p0 is ``p0`` if given, else --sigma2 when given as one value (the confining stress of the
    test: it overrides the file's p0), else the file's. Sets ``args.params_note``, the line of
    the run's summary that says where the values came from ("parameters: the file p.json;
    --phi-g 25 overrides the file's phi_g 20"). A bad file or an option out of range is a
    ValueError (OptionError) of one line naming the key or the option."""
    from .paramfile import override
    from .params import HParams, ParamError, load_params
    path = getattr(args, "params", None)
    base = load_params(path) if path else HParams()
    given = [(o, n, getattr(args, n)) for o, n, _ in PARAM_OPTIONS if getattr(args, n, None) is not None]
    sigma2 = getattr(args, "sigma2", None)
    if p0 is not None:
        given.append(("p0", "p0", float(p0)))
    elif isinstance(sigma2, (int, float)):
        given.append(("--sigma2", "p0", float(sigma2)))
    try:
        P, note = override(base, given, f"the file {path}" if path else "Table I (defaults)",
                           base.replace)
    except ParamError as e:
        raise param_option_error(e) from None
    args.params_note = note
    return P


def record_params(out_dir, params, note="") -> str:
    """Write ``params`` to ``out_dir``/params.json (the --params format: the run repeats with
    ``--params out_dir/params.json``); returns the file name."""
    from .params import save_params
    save_params(os.path.join(out_dir, "params.json"), params, note)
    return "params.json"


class Stage:
    """Where a command is, for the line printed when it is interrupted: ``at(text)`` as it goes
    (or ``at(callable)``, asked only when the line is printed: e.g. the last row a file holds
    then), ``wrote(name)`` for every output file completed."""

    def __init__(self, out_dir=None):
        self.where = "start-up"
        self.out_dir = out_dir
        self.written = []

    def at(self, text):
        self.where = text

    def wrote(self, *names):
        self.written.extend(names)

    def line(self, signame):
        done = (f"complete in {self.out_dir}: {', '.join(self.written)}" if self.written
                else "no output written yet")
        where = self.where() if callable(self.where) else self.where
        return f"interrupted ({signame}) during {where}; {done}"


class Terminated(BaseException):
    """SIGTERM, raised in the main thread like KeyboardInterrupt for Ctrl-C."""


def _in_numba_callback(frame) -> bool:
    """True if ``frame`` runs inside Numba's unpickling callback. Compiled code calls it from C
    (to box every returned array, among others), and Numba's tuple boxing goes on past a failed
    element: an exception raised there comes out as ``SystemError: ... returned a result with an
    exception set`` instead of itself."""
    from numba.core.serialize import _numba_unpickle
    code = _numba_unpickle.__code__
    while frame is not None:
        if frame.f_code is code:
            return True
        frame = frame.f_back
    return False


def _interrupt_handler(exc_type):
    """A signal handler raising ``exc_type`` in the main thread, or, if the signal lands inside a
    callback of compiled code, sending the signal again 5 ms later (that callback returns in
    microseconds, so the exception is raised in Python code)."""
    def handler(signum, frame):
        if "numba.core.serialize" in sys.modules and _in_numba_callback(frame):
            again = threading.Timer(0.005, signal.pthread_kill,
                                    (threading.main_thread().ident, signum))
            again.daemon = True
            again.start()
            return
        raise exc_type()
    return handler


@contextmanager
def _sigterm_raises():
    """SIGTERM raises Terminated and SIGINT KeyboardInterrupt (unless SIGINT is ignored), never
    inside a callback of compiled code (see ``_in_numba_callback``)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {signal.SIGTERM: signal.signal(signal.SIGTERM, _interrupt_handler(Terminated))}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        old[signal.SIGINT] = signal.signal(signal.SIGINT, _interrupt_handler(KeyboardInterrupt))
    try:
        yield
    finally:
        for signum, handler in old.items():
            signal.signal(signum, handler)


def run_cli(parser, argv, run, errors=(ValueError,)) -> int:
    """Parse ``argv`` and call ``run(args, stage)`` -> exit code, with the rules of this module:
    a parse error or one of ``errors`` -> one line ``error: ...``, exit 2; Ctrl-C -> 130,
    SIGTERM -> 143, with ``stage.line(...)``."""
    stage = Stage()
    try:
        args = parser.parse_args(argv)
    except OptionError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    stage.out_dir = getattr(args, "out", None)
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
