"""The calibration's options (``dem.calibrate``): ``CalibrationOptions``, what the search is and
how each test runs, with its one validation (``CalibrationOptions.validate``). ``python -m dem
calibrate`` validates the record before anything is computed or written (exit 2, one line naming
the option), and ``run_calibration`` validates it again, by the same rule: a call of the library
is refused as the command line is.

The rule, written once:

* the range of each value, in one table (``RANGES``): the record's own ranges here, and for an
  option other commands share (--rate, --sigma2; --eps1-max's upper end) the vocabulary's
  (``common.options.VOCABULARY``), read from it (``common.options.vocabulary_range``, as
  ``dem.burst``'s ``BurstOptions`` reads its own), so that the two cannot differ; a bound may be
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

from common.options import OptionError, Range, vocabulary_range

from .cli import DEFAULT_VARY, parse_bounds, parse_seeds, parse_vary
from .search import make_space, model_sets_min
from .targets import SECANT_STRAIN, TARGETS

RECORD = "CalibrationOptions"


def _range(field, kind, lo, hi, lo_open=True, hi_open=True, unit="") -> Range:
    """The record's own range of ``field`` (``common.options.Range``)."""
    return Range(RECORD, field, kind, lo, hi, lo_open, hi_open, unit)


def _vocabulary(field, **ends) -> Range:
    """The range of the vocabulary's term of ``field`` (an option other commands share: its range
    is written there), with the ends ``ends`` gives in place of its own."""
    return vocabulary_range(RECORD, field, **ends)


# The range of every value, once (in the order they are checked: a bound that is another field
# comes after that field's own range).
RANGES = (
    # at least 1 varied + 2 (the rule of the --vary fields' number is below, in validate)
    _range("initial", "int", model_sets_min(1), 4096, False, False),
    _range("batch", "int", 1, 64, False, False),
    # the model of the figures is refitted on every set (leave-one-out over all of them, and the
    # distances between every two: 80 GB of them at 100,000 sets)
    _range("max_evals", "int", 1, 100_000, False, False),
    _vocabulary("rate"),                      # the vocabulary's --rate, as dem biaxial's
    _vocabulary("confining"),                 # the vocabulary's --sigma2
    # the test reaches twice the secant strain at least (the figures read the secant there);
    # its upper end is the vocabulary's --eps1-max
    _vocabulary("eps_max", lo=2 * SECANT_STRAIN, lo_open=False),
    _range("post_peak_strain", "real", 0, "eps_max", unit="-"),
    _range("smooth", "real", 0, 0.05, False, True, unit="-"),
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
    decide_on_first_run: bool = True   # a set whose first run decides it missed runs on no
                                       # other seed (first_run_decides); False: every seed
    stop_decided_runs: bool = False    # a set's first run stops once its records decide
                                       # (InRunDecision; the model takes its figures censored)

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
        if rec.stop_decided_runs and (not rec.decide_on_first_run or len(seeds) < 2):
            why = ("--no-first-run-decision: no first run decides" if not rec.decide_on_first_run
                   else f"--seeds {','.join(map(str, seeds))}: one seed, its run is the set's")
            raise OptionError(f"--stop-decided-runs with {why}; allowed with the first-run "
                              "decision and two seeds or more")
        common = sorted(set(check) & set(seeds))
        if common:
            raise OptionError(f"--check-seeds {','.join(map(str, check))} (--seeds "
                              f"{','.join(map(str, seeds))}): allowed seeds not in --seeds "
                              "(a check on samples the fit did not see; in both: "
                              f"{','.join(map(str, common))})")
        if base is not None:
            make_space(vary, base, rec.bounds)          # ValueError naming --bounds
        return rec
