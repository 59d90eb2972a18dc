"""``hmodel.mixed`` is ``point.mixed`` (moved: written once for any material of the contract); the
name stays so that scripts and imports written before keep working, the same module object."""
import sys

from point import mixed as _module

sys.modules[__name__] = _module
