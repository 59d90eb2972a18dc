"""Parameter files: one JSON format for the parameter record of every law of the material point
(the H-model's ``HParams``, Drucker-Prager's ``DPParams``: ``point.params``) and the DEM's
``DemParams`` (docs/parameters.md), read and written here for all (point.params, hmodel.params
and dem.params).

A file is one JSON object: ``"model"`` ("hmodel", "drucker-prager" or "dem"), every field of the parameter record
by its own name with its value in SI units (angles in degrees), ``"units"`` (field -> unit, a
record for the reader: the values are never converted) and an optional ``"note"`` (free text)::

    {"model": "hmodel", "kn": 1000000.0, ..., "units": {"kn": "N/m", ...}, "note": "..."}

Reading is strict, so that a typo cannot pass silently: every field must be there, nothing else
(but ``model``, ``units``, ``note``), each of its type (a finite number, an integer, or null where
the field allows None), in range (the record's own validation), units if given equal to the
field's; a duplicated key is refused. Every refusal is one line naming the key (``ValueError``:
the CLIs print it as ``error: ...`` and exit 2). ``model`` and ``units`` may be absent: files
written by ``python -m dem params`` before this format (every field, nothing else) still load.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import fields

__all__ = ["RESERVED", "field_kinds", "values_of", "write_params", "read_params", "override"]

RESERVED = ("model", "units", "note")


def field_kinds(cls) -> dict:
    """Field -> "real", "int" or "real or null", from the dataclass annotations of ``cls``
    (fields whose name starts with "_" are derived, not parameters)."""
    kinds = {}
    for f in fields(cls):
        if f.name.startswith("_"):
            continue
        # the annotation as text ("float": a module with postponed annotations) or the type
        # itself (float, float | None: a record written without them)
        t = (f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type)))
        t = t.replace(" ", "")
        kinds[f.name] = {"float": "real", "int": "int", "float|None": "real or null"}[t]
    return kinds


def values_of(params) -> dict:
    """The parameter fields of a record, in their declared order."""
    return {name: getattr(params, name) for name in field_kinds(type(params))}


def write_params(path, params, model: str, units: dict, note: str | None = None) -> None:
    """Write ``params`` to ``path`` (atomically) in the format of this module."""
    from .io import atomic_write_bytes
    doc = {"model": model, **values_of(params), "units": dict(units)}
    if note:
        doc["note"] = note
    atomic_write_bytes(path, (json.dumps(doc, indent=1) + "\n").encode())


def _no_duplicates(pairs):
    d = {}
    for k, v in pairs:
        if k in d:
            raise ValueError(f"the key {k!r} is given twice")
        d[k] = v
    return d


def _json_type(v) -> str:
    return {bool: "true/false", str: "a string", list: "a list", dict: "an object",
            type(None): "null", int: "an integer", float: "a number"}.get(type(v), type(v).__name__)


def _typed(key, v, kind, unit):
    """``v`` of the JSON file as the field's type, or ValueError naming the key."""
    u = f" [{unit}]" if unit not in ("", "-") else ""
    if kind == "real or null" and v is None:
        return None
    if kind == "int":
        if isinstance(v, int) and not isinstance(v, bool):
            return v
        raise ValueError(f"{key} = {json.dumps(v)} ({_json_type(v)}): allowed an integer")
    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
        return float(v)
    allowed = "a finite number" + (" or null" if kind == "real or null" else "")
    raise ValueError(f"{key} = {json.dumps(v)} ({_json_type(v)}): allowed {allowed}{u}")


def read_params(path, cls, model: str, units: dict, build=None, option: str = "--params",
                migrate=None, writer: str | None = None):
    """The record of class ``cls`` in the parameter file ``path``, built by ``build(values)``
    (default ``cls(**values)``, whose validation gives the ranges). ``migrate(doc)``: the
    file's object with keys renamed since under their new names (an old file still loads).
    ``writer``: the command that writes such a file, as the messages name it (default
    ``python -m {model} params``). Every refusal is a ValueError of one line starting
    ``"{option} {path}: "`` and naming the key."""
    head = f"{option} {path}"
    writer = writer or f"python -m {model} params"
    if os.path.isdir(path):
        raise ValueError(f"{head}: is a folder: allowed a parameter file (JSON; {writer} "
                         "--out FILE writes one)")
    try:
        with open(path) as f:
            text = f.read()
    except OSError as e:
        raise ValueError(f"{head}: {(e.strerror or str(e)).lower()}: allowed a parameter file "
                         f"(JSON; {writer} --out FILE writes one)") from None
    except UnicodeDecodeError:
        raise ValueError(f"{head}: not JSON (not text)") from None
    try:
        doc = json.loads(text, object_pairs_hook=_no_duplicates)
    except ValueError as e:
        raise ValueError(f"{head}: not JSON ({e})") from None
    kinds = field_kinds(cls)
    if migrate is not None:
        doc = migrate(doc)
    if not isinstance(doc, dict):
        raise ValueError(f"{head}: allowed a JSON object of the {cls.__name__} fields "
                         f"({writer} --out FILE writes one)")
    if "model" in doc and doc["model"] != model:
        raise ValueError(f"{head}: model = {json.dumps(doc['model'])}: allowed \"{model}\" "
                         f"(a file of {writer})")
    unknown = [k for k in doc if k not in kinds and k not in RESERVED]
    if unknown:
        raise ValueError(f"{head}: unknown key {unknown[0]!r}: allowed the {cls.__name__} fields "
                         f"{', '.join(kinds)} (and model, units, note)")
    missing = [k for k in kinds if k not in doc]
    if missing:
        raise ValueError(f"{head}: missing key {missing[0]!r}: every {cls.__name__} field is "
                         f"required ({writer} --out FILE writes them all)")
    if "note" in doc and not isinstance(doc["note"], str):
        raise ValueError(f"{head}: note = {json.dumps(doc['note'])}: allowed a string")
    if "units" in doc:
        given = doc["units"]
        if not isinstance(given, dict):
            raise ValueError(f"{head}: units = {json.dumps(given)}: allowed an object field -> unit")
        for k, u in given.items():
            if k not in kinds:
                raise ValueError(f"{head}: unknown key 'units.{k}': allowed the {cls.__name__} fields")
            if u != units[k]:
                raise ValueError(f"{head}: units.{k} = {json.dumps(u)}: allowed \"{units[k]}\" (the "
                                 "values are in SI units and degrees; the units are not converted)")
    try:
        values = {k: _typed(k, doc[k], kind, units[k]) for k, kind in kinds.items()}
        return (build or (lambda v: cls(**v)))(values)
    except ValueError as e:
        raise ValueError(f"{head}: {e}") from None


def override(base, given, source: str, replace):
    """``base`` with the command-line options ``given`` on top, and the line that says where the
    values came from. ``given``: (option, field, value) of the options given (not None);
    ``source``: "the file p.json" or the name of the defaults; ``replace(**changes)`` makes the
    new record (and may raise, naming a field). Returns (record, note), e.g. note = "parameters:
    the file p.json; --phi-g 25 overrides the file's 20"."""
    parts = []
    from_file = source.startswith("the file")
    for option, name, value in given:
        old = getattr(base, name)
        if from_file:
            parts.append(f"{option} {value:g} overrides the file's {name} {_g(old)}"
                         if value != old else f"{option} {value:g} (the file's {name} too)")
        else:
            parts.append(f"{option} {value:g} (default {_g(old)})")
    new = replace(**{name: value for _, name, value in given}) if given else base
    return new, "; ".join([f"parameters: {source}"] + parts)


def _g(v):
    return "null" if v is None else f"{v:g}"
