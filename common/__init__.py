"""The ground floor: what every part of the project shares, below the H-model (``hmodel``), the
finite elements (``fem``), the DEM (``dem``) and the cross-check above them (``crosscheck``).

- ``common.io``: the files: atomic writers (a temporary file beside the target, then
  ``os.replace``; the mode of an ordinary new file without ever setting the umask), the one CSV
  writer (each caller's number format a parameter), the one figure writer (``save_figure``);
- ``common.options``: the rules of every command line: the vocabulary of options and its
  validation, output folders, interruption, the compile notice;
- ``common.paramfile``: the parameter files of ``HParams`` and ``DemParams`` (one JSON format);
- ``common.plots``: plot helpers of more than one part (the polar diagram of W2, axes that read);
- ``common.threads``: the one thread chooser (1 or all threads, whichever is faster, measured).

It exists so that the parts share these without importing each other: before it, dem and fem
imported hmodel for its files, options and plots, and dem had a second atomic writer, a second
CSV writer and a second thread chooser. ``common`` imports none of hmodel, fem, dem and
crosscheck (``tests/test_imports.py``); each of them may import it.
"""
