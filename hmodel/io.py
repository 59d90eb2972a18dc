"""Atomic file output: a file is either absent or complete, never half-written; and ``fmt``, a
number of an output line as a reader takes it (no nan, no -0.000)."""
from __future__ import annotations

import os
import re
import tempfile
from contextlib import contextmanager

import numpy as np

__all__ = ["atomic_open", "atomic_write_bytes", "write_csv", "write_table", "save_figure", "read_csv",
           "file_mode", "json_safe", "fmt"]


def fmt(value, spec="", missing="none") -> str:
    """``format(value, spec)`` for an output line, or ``missing`` ("none", "never", ...) when
    there is no such value (None, NaN, inf), right-aligned to the width of ``spec``; a value
    that rounds to zero loses its sign ("-0.000" reads as a bug: it is 0.000 to the digits
    shown)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return format(value, spec)
    x = None if value is None else float(value)
    if x is None or not np.isfinite(x):
        width = re.match(r"(?:.?[<>=^])?[-+ ]?#?0?(\d*)", spec).group(1)
        return missing.rjust(int(width or 0))
    text = format(x, spec)
    mantissa = text.strip().lstrip("+-").split("e")[0]
    if text.strip()[:1] in "+-" and not any(c in "123456789" for c in mantissa):
        text = text.replace("-", " " if text.startswith(" ") else "", 1).replace("+", "", 1)
    return text


def _umask() -> int:
    """The process umask (read without changing it where /proc says it, else set and restored)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    m = os.umask(0o022)
    os.umask(m)
    return m


def file_mode() -> int:
    """The mode an ordinary new file gets: 0666 less the umask (0644 with the usual 022)."""
    return 0o666 & ~_umask()


@contextmanager
def atomic_open(path, mode="w"):
    """Open a temporary file beside ``path``; it replaces ``path`` only if the block succeeds.
    The file gets the mode of an ordinary new file (``file_mode``: 0644 under umask 022), not
    the 0600 of a temporary file."""
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".tmp", dir=d)
    try:
        with os.fdopen(fd, mode) as f:
            yield f
            f.flush()
            os.fchmod(f.fileno(), file_mode())    # mkstemp makes 0600; outputs are ordinary files
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_bytes(path, data: bytes) -> None:
    """Write a whole file at once (temporary file beside it, then os.replace)."""
    with atomic_open(path, "wb") as f:
        f.write(data)


def write_csv(path, columns: dict, fmt: str = "%.10g"):
    """Write equal-length 1D ``columns`` (name -> array) with a header row, atomically.
    Booleans are written as 0/1."""
    names = list(columns)
    cols = [np.asarray(columns[k]) for k in names]
    n = {len(c) for c in cols}
    if len(n) != 1:
        raise ValueError(f"columns of different lengths: { {k: len(c) for k, c in zip(names, cols)} }")
    data = np.column_stack([c.astype(float) for c in cols]) if cols else np.empty((0, 0))
    with atomic_open(path) as f:
        np.savetxt(f, data, delimiter=",", header=",".join(names), comments="", fmt=fmt)


def write_table(path, columns: dict, fmt: str = "%.10g"):
    """Write equal-length columns (name -> sequence) of numbers, booleans (0/1) and text,
    atomically, with a header row: numbers as ``fmt``, a NaN as an empty field (a value that
    does not exist, e.g. the peak of a path that does not peak), text as it is (no commas)."""
    names = list(columns)
    cols = [list(columns[k]) for k in names]
    n = {len(c) for c in cols}
    if len(n) > 1:
        raise ValueError(f"columns of different lengths: { {k: len(c) for k, c in zip(names, cols)} }")

    def cell(v):
        if isinstance(v, str):
            if "," in v or "\n" in v:
                raise ValueError(f"text {v!r} holds a comma or a newline")
            return v
        if isinstance(v, (bool, np.bool_)):
            return "1" if v else "0"
        v = float(v)
        return "" if np.isnan(v) else fmt % v

    with atomic_open(path) as f:
        f.write(",".join(names) + "\n")
        for row in zip(*cols):
            f.write(",".join(cell(v) for v in row) + "\n")


def json_safe(obj):
    """``obj`` with every non-finite float (a value that does not exist, e.g. the peak of a path
    that does not peak) as None, numpy scalars and arrays as Python ones: strict JSON (json.dump
    would write NaN, which JSON readers refuse)."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj


def read_csv(path) -> dict:
    """Read a CSV written by ``write_csv`` into name -> float array."""
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {k: np.atleast_1d(data[k]) for k in data.dtype.names}


def save_figure(fig, path, dpi=130):
    """Save a matplotlib figure as PNG atomically and close it."""
    import matplotlib.pyplot as plt
    with atomic_open(path, "wb") as f:
        fig.savefig(f, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
