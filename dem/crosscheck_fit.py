"""Moved: the H-model fitted to the DEM run is ``python -m crosscheck.fit`` (the same options),
in the package of the cross-check, which stands above hmodel, fem and dem (issue 33). This
module only says so: ``python -m dem.crosscheck_fit`` answers in one line (exit 2)."""
from __future__ import annotations

import sys

LINE = ("error: python -m dem.crosscheck_fit moved to python -m crosscheck.fit, with the same "
        "options (see python -m crosscheck.fit --help)")


def main(argv=None) -> int:
    print(LINE, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
