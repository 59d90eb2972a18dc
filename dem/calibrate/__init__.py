"""Calibration of DEM parameters against the H-model's drained biaxial test (issues 12, 27).

The paper says its DEM parameters "were calibrated to fit with the results obtained with the
H-microdirectional model over the drained biaxial test under 200 kPa".  ``python -m dem
calibrate`` does that fit: it varies chosen float fields of ``DemParams`` so that the DEM's
drained biaxial test (``dem.experiment.run_biaxial``: a seeded compaction of the sample with its
own parameters, then the test at constant axial strain rate, lateral walls at the confining
stress) matches the H-model's (Table I, ``hmodel.driver``) in four figures:

  peak q                                        within TOLERANCES["peak_q"]  (5 %)
  eps1 where q first reaches 95 % of its peak   within TOLERANCES["eps1_95"] (25 %)
  secant modulus (q - q0) / eps1 at 0.25 %      within TOLERANCES["secant"]  (20 %)
  dilatancy ratio 1 - d eps_v / d eps1, the     within TOLERANCES["dilatancy"] (5 %)
  slope of a line over [eps1_95, eps1_95 + 1 %]

(``curve_figures``: q smoothed over a strain window ``smooth``; its peak; the first strain where
the smoothed q reaches PEAK_FRACTION of that peak, interpolated linearly between records -- on
the rising branch, so a plateau or stick-slip at the top, which moves the strain *of* the peak
by percents of strain, moves it little; the secant by linear interpolation of the raw q;
the dilatancy ratio (``dilatancy_ratio``, = -d eps2/d eps1, Rowe's strain-increment ratio,
positive whatever the sample does) on the raw eps_v from eps1_95 on, a stretch that neither the
plateau nor the stop rule moves, a least-squares line averaging the noise (issue 34);
relative errors ``dem / hmodel - 1``).  Each parameter set is run on every seed of ``seeds``
and its figures are the seeds' means; the best set is then run on ``check_seeds``, seeds it was
not fitted on, and the check's verdict is their mean against the targets (``check_mean``).
Four seeds each by default (issue 34): one 2000-disk sample scatters about its set's mean by
about a tolerance (the calibrated set over 16 seeds: one run's sd 4.9 % in peak q, 48 % in
eps1_95, 3.2 % in the secant, 3.1 % in the dilatancy ratio), and a mean of four halves that, to
under half of each tolerance but eps1_95's (docs/dem.md). A set whose first run decides a target
missed by the mean runs on that seed only (``first_run_decides``); with ``stop_decided_runs``
that run stops as soon as its records decide (``InRunDecision``), its figures then known from
below or not at all (``stopped_figures``), which the model takes so (``FigureModel``'s
``censored``, ``model_of``), running on the stopped sets it lacks (``to_complete``).

Search (``surrogate_search``, deterministic): every varied parameter is mapped onto u in [0, 1]
over its range (``Space``: logarithmic for stiffness-like fields, linear otherwise; values
rounded to 4 significant digits).  The start set (the paper's, or --params) is evaluated first,
then a space-filling design (``initial`` scrambled Sobol points, seeded), then rounds where a
model of the four figures (``FigureModel``: a thin-plate-spline RBF of log(figure/target) per
figure, its smoothing chosen by leave-one-out error) proposes the set of least predicted score
at least MIN_DISTANCE from every set evaluated; while the model predicts no set that meets
every target, it explores instead where its error bar leaves the most room for one (the error
bar: MARGIN_SIGMAS leave-one-out errors at a set evaluated, growing with the distance to it at
the largest slope seen between neighbouring sets).  It stops when an evaluated set meets every
target; when the model shows that no set in the box can (``analyse``: no point meets them all
even with each target widened by that error bar; it then names the targets no set meets and
the pairs no set meets together); or at ``max_evals`` sets.
Every batch is a set of independent runs (one thread each) spread over local processes or a dask
cluster (``dem.probes._map``); the search only decides once a whole batch is in, so the result
does not depend on where or in which order the runs finished.
Ranking: a set meeting all four targets first, then the smaller score sum((err_i / tol_i)^2).

Checkpoint: DIR/evaluations.jsonl, a header line (the options that define the search) and one
line per finished run (its parameters incl. the seed, curve and figures).  ``resume=True``
re-drives the same deterministic search and takes every run already there (and any finished in
DIR/work/ but not yet logged) instead of running it; a run interrupted half-way continues from
its run_biaxial checkpoint in DIR/work/<key>/.  A folder made with other options is refused;
one made with the three targets of before the dilatancy is read with four (its curves hold eps_v;
one line says so).

Options: ``CalibrationOptions`` (``options``), the search's and each test's, validated once by one
rule (a table of ranges, ``RANGES``, and the rules between two values) by the command line before
anything runs and by ``run_calibration`` (a record, or its keywords).

Modules: ``targets`` (the four figures of a curve, their tolerances, the H-model's curve),
``cli`` (the command line's --vary, --bounds and --seeds), ``options`` (``CalibrationOptions``),
``search`` (the search space, the
model of the figures and the search: pure numerics, no DEM run), ``evaluation`` (one DEM run in a
worker, a set's record from its seeds, the checkpoint), ``report`` (the CSVs, the verdict,
report.md), ``figures``, ``command`` (``run_calibration``).
"""
from .targets import (DECIDE_Z, DILATANCY_STRAIN, FIGURE_TEXT, HMODEL_EPS_MIN,
                      ONE_RUN_SCATTER, PEAK_FRACTION, SCATTER_DISKS, SECANT_STRAIN, TARGETS,
                      TOLERANCES, InRunDecision, compare, curve_figures, decided_in_run,
                      dilatancy_ratio, first_run_decides, hmodel_curve, one_run_scatter, rank,
                      score_at_least, smoothed, stopped_figures)
from .cli import (DEFAULT_VARY, NUMERICAL, bounds_type, calibratable_fields, parse_bounds,
                  parse_seeds, parse_vary, resolve_field, seeds_type, vary_type)
from .search import (CENSORED, DEFAULT_BOUNDS, DENSE_POINTS, FigureModel, LOG_FIELDS,
                     MARGIN_SIGMAS, MIN_DISTANCE, SMOOTHINGS, Space, analyse, dense_points,
                     identifiability, initial_design, make_space, model_of, model_sets_min,
                     nearest_distance, short_figures, space_dim_min, surrogate_search,
                     to_complete)
from .options import CalibrationOptions, RANGES
from .evaluation import (FORMAT, FORMAT_VERSION, RESUME_FREE, current_params, params_key,
                         read_checkpoint)
from .evaluation import _header  # noqa: F401 (the checkpoint's header, which tests build)
from .report import CSV_FIXED, FIGURE_COLS, RUN_FIXED
from .figures import SEED_COLORS, START_SHADES, redraw_figures
from .command import run_calibration

__all__ = ["analyse", "bounds_type", "CalibrationOptions", "CENSORED", "InRunDecision",
           "model_of", "score_at_least", "short_figures", "stopped_figures", "to_complete", "calibratable_fields", "compare",
           "CSV_FIXED",
           "current_params", "curve_figures", "DECIDE_Z", "decided_in_run", "first_run_decides",
           "one_run_scatter", "ONE_RUN_SCATTER", "SCATTER_DISKS", "DEFAULT_BOUNDS", "DILATANCY_STRAIN", "dilatancy_ratio", "DEFAULT_VARY", "DENSE_POINTS",
           "dense_points", "FIGURE_COLS", "FIGURE_TEXT", "FigureModel", "FORMAT", "FORMAT_VERSION", "hmodel_curve",
           "HMODEL_EPS_MIN", "identifiability", "initial_design", "LOG_FIELDS", "make_space",
           "MARGIN_SIGMAS", "MIN_DISTANCE", "model_sets_min", "nearest_distance", "NUMERICAL",
           "params_key", "parse_bounds", "parse_seeds", "parse_vary", "PEAK_FRACTION", "RANGES",
           "rank", "read_checkpoint",
           "redraw_figures", "resolve_field", "RESUME_FREE", "run_calibration", "RUN_FIXED",
           "SECANT_STRAIN", "SEED_COLORS", "seeds_type", "smoothed", "SMOOTHINGS", "Space",
           "space_dim_min", "START_SHADES", "surrogate_search", "TARGETS", "TOLERANCES",
           "vary_type"]
