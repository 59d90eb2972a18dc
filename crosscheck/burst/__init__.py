"""The cross-check's burst section: failure made to happen in the three parts side by side
(docs/burst.md, paper Eq. 1).

For each ratio R and start fraction f, the material point (``hmodel.burst``), the FE perfect
specimen (``fem.burst``) and the DEM sample of the cross-check (``dem.burst``, from the states its
biaxial test saved) follow the proportional strain path d eps2 = R d eps1, find where
c = s1 + R s2 peaks (W2 = 0 along the path), and hold c below and past that peak. The section
states, with the run's numbers, whether each part failed exactly where W2 vanished along the path
(below: equilibrium, past: failure), and how the c peaks compare with the first W2 = 0 of the
H-model's directional analysis and with the FE's first lam_min(K_s) <= 0 on the drained path.

Modules: ``part`` (the runs of the three parts and the section's numbers), ``figures``,
``report`` (the section of report.md).
"""
from .figures import burst_eq1_figure, burst_figure, w2_path_figure
from .part import (BURST_FRACTIONS, BURST_RATIOS, burst_conclusions, burst_jobs, burst_part,
                   w2_paths)
from .report import burst_report_lines

__all__ = ["burst_part", "burst_jobs", "burst_conclusions", "burst_figure", "burst_eq1_figure",
           "burst_report_lines", "w2_paths", "w2_path_figure",
           "BURST_RATIOS", "BURST_FRACTIONS"]
