"""The files of every part: atomic writers (a file is either absent or complete, never
half-written), the one CSV writer, the one figure writer, and ``fmt``, a number of an output line
as a reader takes it (no nan, no -0.000).

An atomic write goes to a temporary file beside the target (same folder, so same file system),
which replaces it (``os.replace``) only once the write has succeeded: an interrupted run leaves
the previous file, or none, never half of one. The temporary file is created with mode 0666 and
the kernel takes the umask off (``os.open``), so the output gets the mode of an ordinary new file
(0644 under umask 022) without this process ever setting its umask (``os.umask`` changes it for
every thread at once: another thread creating a file at that moment would get the wrong mode).
"""
from __future__ import annotations

import csv
import io as _io
import os
import re
import secrets
import tempfile
from contextlib import contextmanager

import numpy as np

__all__ = ["atomic_open", "atomic_path", "atomic_write_bytes", "write_csv",
           "save_figure", "read_csv", "file_mode", "json_safe", "fmt", "REPR"]


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
    """The process umask, read without changing it: from /proc where it says it, else from the
    mode of a file created with 0666 (the kernel takes the umask off)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    fd, tmp = _create_beside(os.path.join(tempfile.gettempdir(), "umask"))
    try:
        return 0o777 & ~os.fstat(fd).st_mode & 0o666
    finally:
        os.close(fd)
        os.unlink(tmp)


def file_mode() -> int:
    """The mode an ordinary new file gets: 0666 less the umask (0644 with the usual 022)."""
    return 0o666 & ~_umask()


def _create_beside(path):
    """(fd, name) of a new empty temporary file beside ``path`` (write only), created with mode
    0666 less the umask (by the kernel, as for any new file), never an existing one."""
    d, base = os.path.split(os.path.abspath(os.fspath(path)))
    for _ in range(100):
        tmp = os.path.join(d, f".{base}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0),
                           0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {path}")


@contextmanager
def atomic_path(path):
    """The name of a temporary file beside ``path`` (created empty, the mode of an ordinary new
    file), for a writer that takes a file name (meshio); it replaces ``path`` only if the block
    succeeds, else it is removed."""
    path = os.fspath(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fd, tmp = _create_beside(path)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


@contextmanager
def atomic_open(path, mode="w", fsync=True):
    """Open a temporary file beside ``path``; it replaces ``path`` only if the block succeeds
    (else it is removed, and ``path`` is as it was). The file gets the mode of an ordinary new
    file (``file_mode``: 0644 under umask 022). ``fsync``: push the data to the disk before the
    replacement (off for a file rewritten every step whose data another file holds: fem's
    fields.xdmf)."""
    path = os.fspath(path)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fd, tmp = _create_beside(path)
    try:
        with os.fdopen(fd, mode) as f:
            yield f
            f.flush()
            if fsync:
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_bytes(path, data: bytes, fsync=True) -> None:
    """Write a whole file at once (temporary file beside it, then os.replace)."""
    with atomic_open(path, "wb", fsync) as f:
        f.write(data)


# the number format of dem's tables: every float as Python writes it (the shortest text that
# reads back to the same bits: published curves are compared to the bit), other values as the
# csv module writes them (an int as it is, a bool as True/False, None as an empty field)
REPR = "repr"


def write_csv(path, columns, rows=None, fmt: str = "%.10g", nan: str = "nan"):
    """The one CSV writer: a header row, then a line per row, written atomically.

    ``columns``: name -> equal-length 1D sequence (``rows`` None); or the header (a list of
    names) with ``rows`` the rows (sequences in the header's order). The number format is the
    caller's: ``fmt`` a %-format (the default "%.10g", 10 significant digits: the files of the
    H-model, fem and the cross-check), every number (int or float) written as ``fmt % float(v)``,
    a boolean as 0/1, a NaN (a value that does not exist, e.g. the peak of a path that does not
    peak) as ``nan`` ("nan", or "" for an empty field); or ``REPR`` (dem's tables: see REPR). Text
    is written as it is (quoted where it holds a comma, as the csv module does)."""
    if rows is None:
        header = list(columns)
        cols = [columns[k] for k in header]
        lengths = {k: len(c) for k, c in zip(header, cols)}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"columns of different lengths: {lengths}")
        rows = zip(*cols)
    else:
        header = list(columns)

    if fmt == REPR:
        def cell(v):
            if isinstance(v, (float, np.floating)):
                return nan if np.isnan(v) else repr(float(v))
            return v
    else:
        def cell(v):
            if isinstance(v, str):
                return v
            if isinstance(v, (bool, np.bool_)):
                return "1" if v else "0"
            v = float("nan") if v is None else float(v)
            return nan if np.isnan(v) else fmt % v

    buf = _io.StringIO()
    wr = csv.writer(buf, lineterminator="\n")
    wr.writerow(header)
    for row in rows:
        wr.writerow([cell(v) for v in row])
    atomic_write_bytes(path, buf.getvalue().encode())


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
    """Read a CSV of numbers written by ``write_csv`` into name -> float array."""
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {k: np.atleast_1d(data[k]) for k in data.dtype.names}


def save_figure(fig, path, dpi=130):
    """Save a matplotlib figure as PNG atomically and close it."""
    import matplotlib.pyplot as plt
    with atomic_open(path, "wb") as f:
        fig.savefig(f, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
