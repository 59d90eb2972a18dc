"""The calibration's options (``dem.calibrate``): ``CalibrationOptions``, what the search is and
how each test runs, with its one validation (``CalibrationOptions.validate``). ``python -m dem
calibrate`` validates the record before anything is computed or written (exit 2, one line naming
the option), and ``run_calibration`` validates it again, by the same rule: a call of the library
is refused as the command line is.

The rule, written once:

* the range of each value, in one table (``RANGES``): the record's own ranges here, and for an
  option other commands share (--rate, --sigma2; --eps1-max's upper end) the vocabulary's
  (``common.options.VOCABULARY``), read from it, so that the two cannot differ; a bound may be
  another value of the record (--post-peak-strain < --eps1-max), checked after it;
* the rules between two values (``CalibrationOptions.validate``): --initial at least the number
  of --vary fields + 2 (``search.model_sets_min``: the model of the figures needs that many
  sets), --check-seeds none of --seeds, and, given the start set, --bounds of the --vary fields
  only, each inside what DemParams allows (``search.make_space``);
* the form of --vary, --bounds, --seeds and --check-seeds: the parsers of ``cli``, which the
  command line's types call too.

An error is one line ``--option value: allowed ...`` (an ``OptionError``, a ValueError).
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from typing import NamedTuple

from common.options import VOCABULARY, OptionError, option_of

from .cli import DEFAULT_VARY, parse_bounds, parse_seeds, parse_vary
from .search import make_space, model_sets_min
from .targets import SECANT_STRAIN, TARGETS

RECORD = "CalibrationOptions"


class Range(NamedTuple):
    """The allowed values of a field: an integer or a finite real in (lo, hi) (open or closed
    ends; None: no bound; a field's name: that field's value, checked before)."""
    field: str
    kind: str                   # "int" or "real"
    lo: float | str | None
    hi: float | str | None
    lo_open: bool = True
    hi_open: bool = True
    unit: str = ""

    @property
    def option(self) -> str:
        return option_of(RECORD, self.field)

    def _end(self, bound, rec):
        """(the bound's value, its text): a number, or another field's option."""
        if isinstance(bound, str):
            return (None if rec is None else getattr(rec, bound)), option_of(RECORD, bound)
        return bound, f"{bound:g}"

    def text(self) -> str:
        """"1 <= value <= 64", "0 < value < --eps1-max" (as a help says it: no unit, no
        kind)."""
        lt = lambda is_open: "<" if is_open else "<="
        lo, hi = self._end(self.lo, None)[1], self._end(self.hi, None)[1]
        if self.hi is None:
            rng = f"value {'>' if self.lo_open else '>='} {lo}"
        elif self.lo is None:
            rng = f"value {lt(self.hi_open)} {hi}"
        else:
            rng = f"{lo} {lt(self.lo_open)} value {lt(self.hi_open)} {hi}"
        return rng

    def check(self, rec):
        """The value of the field in ``rec`` as an int or a float; OptionError otherwise."""
        v = getattr(rec, self.field)
        ok = (isinstance(v, numbers.Integral) if self.kind == "int" else
              isinstance(v, numbers.Real) and math.isfinite(v)) and not isinstance(v, bool)
        if ok:
            v = int(v) if self.kind == "int" else float(v)
            for bound, is_open, above in ((self.lo, self.lo_open, True),
                                          (self.hi, self.hi_open, False)):
                b = self._end(bound, rec)[0]
                if b is not None:
                    ok = ok and ((v > b if is_open else v >= b) if above else
                                 (v < b if is_open else v <= b))
        if not ok:
            others = [b for b in (self.lo, self.hi) if isinstance(b, str)]
            given = "".join(f" ({option_of(RECORD, b)} {getattr(rec, b)!r})" for b in others)
            unit = f" [{self.unit}]" if self.unit not in ("", "-", None) else ""
            kind = "an integer " if self.kind == "int" else ""
            raise OptionError(f"{self.option} {getattr(rec, self.field)!r}{given}: allowed "
                              f"{kind}{self.text()}{unit}")
        return v


def _vocabulary(field, **ends) -> Range:
    """The range of the vocabulary's term of ``field`` (an option other commands share: its range
    is written there), with the ends ``ends`` gives in place of its own."""
    t = VOCABULARY[option_of(RECORD, field)]
    r = dict(lo=t.lo, hi=t.hi, lo_open=t.lo_open, hi_open=t.hi_open)
    r.update(ends)
    return Range(field, "int" if t.kind == "int" else "real", unit=t.unit or "", **r)


# The range of every value, once (in the order they are checked: a bound that is another field
# comes after that field's own range).
RANGES = (
    # at least 1 varied + 2 (the rule of the --vary fields' number is below, in validate)
    Range("initial", "int", model_sets_min(1), 4096, False, False),
    Range("batch", "int", 1, 64, False, False),
    # the model of the figures is refitted on every set (leave-one-out over all of them, and the
    # distances between every two: 80 GB of them at 100,000 sets)
    Range("max_evals", "int", 1, 100_000, False, False),
    _vocabulary("rate"),                      # the vocabulary's --rate, as dem biaxial's
    _vocabulary("confining"),                 # the vocabulary's --sigma2
    # the test reaches twice the secant strain at least (the figures read the secant there);
    # its upper end is the vocabulary's --eps1-max
    _vocabulary("eps_max", lo=2 * SECANT_STRAIN, lo_open=False),
    Range("post_peak_strain", "real", 0, "eps_max", unit="-"),
    Range("smooth", "real", 0, 0.05, False, True, unit="-"),
)
_RANGE = {r.field: r for r in RANGES}


@dataclasses.dataclass(frozen=True)
class CalibrationOptions:
    """What the calibration searches and how each of its tests runs (``run_calibration``'s
    options but the start set, the output folder and where the runs go). ``validate`` checks it
    (module docstring) and gives it in its checked form: --vary and --bounds as DemParams fields,
    the seeds as tuples, the counts as int, the rest as float."""
    target: str = "hmodel"             # the curve fitted (TARGETS)
    vary: str | tuple = DEFAULT_VARY   # DemParams fields (or option names), or comma-separated
    bounds: object = None              # {name: (lo, hi)}, NAME=LO:HI,... or None (defaults)
    seeds: tuple = (1, 2, 3, 4)        # every set is run on each (its figures: their means)
    check_seeds: tuple = (5, 6, 7, 8)  # the best set is then run on each, the check their mean
                                       # ((): no check)
    initial: int = 16                  # sets of the Sobol design
    batch: int = 1                     # sets the model proposes per round
    max_evals: int = 32                # sets at most, the start set included
    rate: float = 0.01                 # axial strain rate of each test [1/s]
    confining: float = 200e3           # sigma2 of each test [Pa]
    eps_max: float = 0.035             # each test ends at this axial strain at most [-]
    post_peak_strain: float = 0.01     # ... or this far past its peak [-]
    smooth: float = 0.001              # strain window of q's moving average for the peak [-]

    @staticmethod
    def allowed_text(field) -> str:
        """The range of ``field`` as the command's help says it ("0 < value <= 10")."""
        return _RANGE[field].text()

    def validate(self, base=None) -> "CalibrationOptions":
        """The record in its checked form, or an OptionError of one line naming the option and
        what it allows. ``base`` (the start set, DemParams): --bounds checked against the
        --vary fields and DemParams' ranges too."""
        if self.target not in TARGETS:
            raise OptionError(f"--target {self.target!r}: allowed one of {', '.join(TARGETS)}")

        def parsed(option, parse, value):
            try:
                return parse(value)
            except ValueError as e:
                raise OptionError(f"{option} {e}") from None

        text = lambda v: v if isinstance(v, str) else ",".join(map(str, v))
        vary = parsed("--vary", parse_vary, text(self.vary))
        bounds = (None if self.bounds is None else
                  tuple(parsed("--bounds", parse_bounds, self.bounds).items()))
        seeds = parsed("--seeds", parse_seeds, text(self.seeds))
        check = (parsed("--check-seeds", parse_seeds, text(self.check_seeds))
                 if self.check_seeds else ())
        rec = dataclasses.replace(self, vary=vary, bounds=bounds, seeds=seeds, check_seeds=check)
        rec = dataclasses.replace(rec, **{r.field: r.check(rec) for r in RANGES})
        # the rules between two values
        least = model_sets_min(len(vary))
        if rec.initial < least:
            raise OptionError(f"--initial {rec.initial} (--vary {','.join(vary)}): allowed an "
                              f"integer {least} <= value <= {_RANGE['initial'].hi} (the number "
                              "of --vary fields + 2 at least: the model of the figures needs "
                              "that many sets)")
        common = sorted(set(check) & set(seeds))
        if common:
            raise OptionError(f"--check-seeds {','.join(map(str, check))} (--seeds "
                              f"{','.join(map(str, seeds))}): allowed seeds not in --seeds "
                              "(a check on samples the fit did not see; in both: "
                              f"{','.join(map(str, common))})")
        if base is not None:
            make_space(vary, base, rec.bounds)          # ValueError naming --bounds
        return rec
