"""The H-model fitted to the project's 12,000-disk DEM curve, its directional analysis and
bifurcation domain beside the DEM's, as fractions of each peak and in eta (issue 19, part 2;
docs/fit.md).

    python -m crosscheck.fit [--dem docs/gallery/full] [--out docs/gallery/fit_dem12000]

(formerly ``python -m dem.crosscheck_fit``) runs, in order, by library calls with the fitted
HParams record: the fit (``hmodel.fit.fit_curve``) of DEM/biaxial.csv (OUT/params.json,
fig_fit.png, ...); the directional analysis (``hmodel.experiment.directional_analysis``) with
the fitted record at the fraction of the fitted model's peak where the DEM's lower boundary lies
(OUT/probes/); its bifurcation domain (``hmodel.experiment.bifurcation_domain``) at the fitted
confining stress (OUT/domain/); then, for every state of the DEM's domain
(DEM/domain12000/domain.csv, boundaries.json), the H-model's minimum second-order work at the
same fraction of its own peak and at the same eta, written to OUT/comparison.csv,
comparison.json, fig_comparison.png, fig_domain_pq.png and comparison.md.

A command of its own rather than a subcommand of ``python -m crosscheck``: that one runs the
cross-check itself with no subcommand word (``python -m crosscheck --out DIR``, as ``python -m
dem crosscheck`` did), and argparse cannot give a command both its own options and optional
subcommands without making a stray word ambiguous; this job reads a finished DEM run instead of
running one, with options of its own.

Modules: ``run`` (the run, by library calls), ``compare`` (the numbers), ``figures``, ``report``
(comparison.md and its verdicts), ``__main__`` (the command line).
"""
from .compare import compare, eulerian_w2, hmodel_state, read_dem_domain, second_optimum
from .report import bracket, markdown, verdicts
from .run import NotFittable, fit_to_curve, hmodel_beside_the_dem, run_fit

__all__ = ["run_fit", "fit_to_curve", "hmodel_beside_the_dem", "NotFittable", "read_dem_domain",
           "eulerian_w2", "hmodel_state", "compare", "second_optimum", "verdicts", "markdown",
           "bracket"]
