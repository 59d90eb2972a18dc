"""The parameters of any law of the material point: its parameter file (the format of
``common.paramfile``, whose "model" names the law) and the command-line options of its fields
(the terms of ``common.options.VOCABULARY`` that list them: ``--kn`` for ``HParams.kn``,
``--shear-modulus`` for ``DPParams.G``; ``--sigma2`` for every law's p0). ``hmodel.params`` is
this for the H-model alone (``python -m hmodel``); ``python -m point`` takes every law.

One loader of every law's file (``load_params``: the file's "model" finds the law), one writer
(``save_params``, ``record_params``), and ``params_from``: the record of a command, from
``--params FILE`` or ``--model NAME`` (the law's default record) with the options given on top,
and the line that says where the values came from. An option of another law's field is refused
in one line naming the option and both laws; an option out of range in one line naming the
option (the record's own validation gives the range: ``ParamError``).
"""
from __future__ import annotations

import json
import os

from common import options as opt
from common.options import VOCABULARY, OptionError, option_of
from common.paramfile import override, read_params, write_params

from .contract import _BUILTIN, MATERIALS, ParamError, material_named, material_of

__all__ = ["DEFAULT_LAW", "known_laws", "writer_of", "file_model", "law_of_file", "load_params",
           "save_params", "record_params", "record_options", "param_options", "param_option_error",
           "add_param_options", "choose_law", "params_from"]

# the law of ``python -m point`` when neither --model nor --params names one: the paper's
DEFAULT_LAW = "hmodel"


def known_laws() -> list:
    """The names of the laws a command line offers: the built-in ones, then those registered
    (``point.register``) in this process (a script that registers its own law and calls
    ``point.cli.main``)."""
    return list(_BUILTIN) + [n for n in MATERIALS if n not in _BUILTIN]


def writer_of(law) -> str:
    """The command that writes a parameter file of ``law`` (the messages name it)."""
    return "python -m hmodel params" if law.name == "hmodel" else \
        f"python -m point params --model {law.name}"


def file_model(path):
    """The "model" of the parameter file ``path``; None where the file cannot be read as a JSON
    object or names none (``read_params`` then says what is wrong, or reads it as the default
    law's: files written before the "model" key)."""
    try:
        with open(path) as f:
            doc = json.load(f)
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return doc.get("model") if isinstance(doc, dict) else None


def law_of_file(path, option: str = "--params"):
    """The law a parameter file names (its "model"; the default law where it names none), or a
    ValueError of one line naming the file and the laws allowed."""
    name = file_model(path)
    if name is None:
        return material_named(DEFAULT_LAW)
    if not isinstance(name, str) or name not in known_laws():
        raise ValueError(f"{option} {path}: model = {json.dumps(name)}: allowed one of "
                         f"{', '.join(known_laws())} (a file of python -m point params; a DEM "
                         "file is python -m dem's)")
    return material_named(name)


def load_params(path, option: str = "--params", law=None):
    """The parameter record of the file ``path``: of the law its "model" names, or of ``law``
    (the file must then be of that law). Every refusal is a ValueError of one line naming the
    file and the key (``common.paramfile.read_params``)."""
    law = law_of_file(path, option) if law is None else law

    def build(values):
        try:
            return law.params_type(**values)
        except ParamError as e:
            raise ValueError(f"{e.name} = {e.value!r} is out of range: allowed {e.allowed}") from None
    return read_params(path, law.params_type, law.name, law.units, build, option,
                       writer=writer_of(law))


def save_params(path, params, note: str | None = None) -> None:
    """Write ``params`` (any law's record) as a parameter file (docs/parameters.md)."""
    law = material_of(params)
    write_params(path, params, law.name, law.units, note)


def record_params(out_dir, params, note: str = "") -> str:
    """Write ``params`` to ``out_dir``/params.json (the --params format: the run repeats with
    ``--params out_dir/params.json``); returns the file name."""
    save_params(os.path.join(out_dir, "params.json"), params, note)
    return "params.json"


# -- the command-line options of a law's fields ------------------------------------------------
def record_options(record: str) -> tuple:
    """(option, field) of every field of the record named ``record`` ("HParams") that has a term
    in the vocabulary, p0 left out (the commands' --sigma2), in the vocabulary's order."""
    return tuple((t.name, f.split(".", 1)[1]) for t in VOCABULARY.values() for f in t.fields
                 if f.startswith(record + ".") and f != record + ".p0")


def param_options(law) -> tuple:
    """``record_options`` of ``law``'s parameter record."""
    return record_options(law.params_type.__name__)


def param_option_error(e, record: str, options=None) -> OptionError:
    """The OptionError of a record's ``ParamError`` ``e``, naming the command-line option of the
    field (``--phi-g`` for HParams.phi_g, ``--sigma2`` for p0, or ``options[field]``)."""
    name = (options or {}).get(e.name) or option_of(record, e.name)
    return OptionError(f"{name} {e.value!r} is out of range: allowed {e.allowed}")


def _add_fields(group, law, seen) -> None:
    d = law.params_type()
    rec = law.params_type.__name__
    none_means = getattr(law.params_type, "none_means", {})
    for option, name in param_options(law):
        if option in seen:          # a term two laws share: one option serves both
            continue
        seen.add(option)
        v = getattr(d, name)
        shown = (f"null ({none_means[name]})" if v is None and name in none_means else
                 "null" if v is None else format(v, "g"))
        opt.add(group, option, record=rec, metavar=name.upper(), dest=name,
                default_text=f"the file's, else {law.defaults_name}'s {shown}")


def add_param_options(ap, law=None, file_note: str | None = None) -> None:
    """The parameter options of a command, all None unless given (the file or the law's defaults
    supply the rest: ``params_from``; the record checks them). With ``law``: --params FILE and
    an option of every field of that law but p0 (a command line of one law, ``python -m
    hmodel``). Without: --params FILE, --model and the options of every known law, each law's
    in a group of its own (``python -m point``). ``file_note``: what --params takes, where a
    command of one law's options takes the files of other laws too (``python -m fem``)."""
    seen = set()
    if law is not None:
        g = ap.add_argument_group(f"model parameters ({law.defaults_name} unless --params FILE; "
                                  "an option given overrides the file)")
        opt.add(g, "--params", metavar="FILE", default_text=law.defaults_name,
                note=file_note or f"of the {law.label or law.name}: {writer_of(law)} --out FILE")
        _add_fields(g, law, seen)
        return
    laws = known_laws()
    g = ap.add_argument_group("the law (its parameters: the law's defaults unless --params FILE; "
                              "an option given overrides the file)")
    opt.add(g, "--params", metavar="FILE", default_text="the defaults of the law",
            note="of any law, its \"model\" naming the law: python -m point params --out FILE")
    opt.add(g, "--model", choices=laws, metavar="NAME",
            default_text=f"the \"model\" of --params FILE, else {DEFAULT_LAW}")
    for name in laws:
        law = material_named(name)
        g = ap.add_argument_group(f"parameters of {name} ({law.label or name}; with --model "
                                  f"{name} or a file of it; {law.defaults_name} unless --params "
                                  "FILE)")
        _add_fields(g, law, seen)


def choose_law(args):
    """(law, why) of a command of any law: the law of ``--params FILE`` (its "model"), else of
    ``--model NAME``, else the default law; ``why`` says which. Both given and different: an
    OptionError naming both."""
    named = getattr(args, "model", None)
    path = getattr(args, "params", None)
    if path:
        law = law_of_file(path)
        if named is not None and named != law.name:
            raise OptionError(f"--model {named}: the file {path} is of {law.name} (its \"model\"): "
                              f"allowed {law.name}, or --model left out")
        return law, f"the \"model\" of --params {path}"
    if named is not None:
        return material_named(named), f"--model {named}"
    return material_named(DEFAULT_LAW), "the default law (no --model, no --params)"


def _refuse_foreign(args, law, why) -> None:
    """An option of another law's field, given: one line naming the option and both laws."""
    mine = {o for o, _ in param_options(law)}
    for name in known_laws():
        other = material_named(name)
        if other is law:
            continue
        for option, field in param_options(other):
            if option not in mine and getattr(args, field, None) is not None:
                raise OptionError(f"{option} is an option of {other.name}'s parameters, not of "
                                  f"{law.name}, the law of this run ({why}): allowed the options "
                                  f"of {law.name} (see --help), or --model {other.name}")


def params_from(args, law=None, p0=None, base=None):
    """The parameter record of a command: the --params file (or the law's defaults), then the
    options given on top; p0 is ``p0`` if given, else --sigma2 when given as one value (the
    confining stress of the test: it overrides the file's p0), else the file's. ``law``: the law
    of a command line of one law; None: ``choose_law`` (--params, --model), and an option of
    another law is refused. Sets ``args.params_note``, the line of the run's summary that says
    where the values came from ("parameters: the file p.json; --phi-g 25 overrides the file's
    phi_g 20"). ``base``: the --params file's record already read. A bad file or an option out
    of range is a ValueError (OptionError) of one line naming the key or the option."""
    path = getattr(args, "params", None)
    if law is None:
        law, why = choose_law(args)
        _refuse_foreign(args, law, why)
    if base is None:
        base = load_params(path, law=law) if path else law.params_type()
    given = [(o, n, getattr(args, n)) for o, n in param_options(law)
             if getattr(args, n, None) is not None]
    sigma2 = getattr(args, "sigma2", None)
    if p0 is not None:
        given.append(("p0", "p0", float(p0)))
    elif isinstance(sigma2, (int, float)):
        given.append(("--sigma2", "p0", float(sigma2)))
    try:
        P, note = override(base, given, f"the file {path}" if path else
                           f"{law.defaults_name} (defaults)", base.replace)
    except ParamError as e:
        raise param_option_error(e, law.params_type.__name__) from None
    args.params_note = note
    return P
