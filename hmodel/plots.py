"""``hmodel.plots`` is ``point.plots`` (moved: the figures of the material point of any law); the
name stays so that scripts and imports written before keep working, the same module object."""
import sys

from point import plots as _module

sys.modules[__name__] = _module
