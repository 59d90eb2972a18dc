"""The cross-check of the three parts: the H-model material point (``hmodel``), the FE biaxial
specimen (``fem``) and the DEM sample (``dem``) side by side and against the paper (sections 3-5,
Eq. 1), and the H-model fitted to a DEM run (``crosscheck.fit``).

Why a package of its own, beside ``hmodel``, ``fem`` and ``dem``: the cross-check imports all
three, and none of them may import it. It stands above them; inside one of them (it lived in
``dem`` until issue 33) it made that part import another (dem imported fem for it alone). The
import rule, read from the source by tests/test_imports.py: hmodel, fem and dem import nothing of
``crosscheck``; dem imports nothing of fem.

Modules:
  ``parts``        the three parts, run as the paper runs them (``hmodel_part``, ``fem_part``,
                   ``dem_part``) and the DEM's comparison state (``comparison_state``);
  ``conclusions``  the paper's section-5 conclusions as numbers (a pure function of the parts);
  ``figures``      the side-by-side figures (``polar_figure`` and the rest);
  ``report``       report.md;
  ``run``          ``run_crosscheck``: all of it into one folder;
  ``burst``        the burst section (``part``, ``figures``, ``report``);
  ``fit``          the H-model fitted to the DEM's drained curve, domains compared
                   (``python -m crosscheck.fit``);
  ``__main__``     ``python -m crosscheck`` (the options of ``python -m dem crosscheck``, which
                   now answers in one line where it moved).
"""
from .conclusions import conclusions
from .parts import comparison_state, dem_part, fem_part, hmodel_part
from .report import write_report
from .run import DEFAULT_FULL, DEFAULT_SMALL, run_crosscheck

__all__ = ["run_crosscheck", "conclusions", "hmodel_part", "fem_part", "dem_part", "write_report",
           "comparison_state", "DEFAULT_SMALL", "DEFAULT_FULL"]
