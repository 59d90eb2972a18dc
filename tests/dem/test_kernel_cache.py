"""The kernels' cache follows every file of the package (``dem.kernels._drop_stale_cache``).

Numba's cache index holds the hash of a function's own file only: a kernel of one module that
inlines another module's function (``advance`` and the contact law) would be loaded from the
cache with the old code after the other module changed. The package drops its cached kernels
when any of its files changed, so they compile again.
"""
import os
import shutil
import subprocess
import sys

import dem.kernels
from dem.kernels import _drop_stale_cache


def _touch(path, text="x"):
    with open(path, "w") as f:
        f.write(text)


def test_cached_kernels_are_dropped_when_any_source_changes(tmp_path):
    src, cache = tmp_path / "pkg", tmp_path / "cache"
    src.mkdir()
    cache.mkdir()
    _touch(src / "a.py", "A = 1\n")
    _touch(src / "b.py", "B = 1\n")
    ours = ["a.f-3.py312.nbi", "a.f-3.py312.0.nbc", "b.g-10.py312.nbi"]
    others = ["a.cpython-312.pyc", "c.h-1.py312.nbi", "ab.k-1.py312.nbi"]

    def fill():
        for name in ours + others:
            _touch(cache / name)

    fill()
    assert _drop_stale_cache(src, cache)                 # no record yet: dropped
    assert sorted(os.listdir(cache)) == sorted(others + ["kernels-sources.sha256"])
    fill()
    assert not _drop_stale_cache(src, cache)             # same sources: kept
    assert all((cache / n).exists() for n in ours)
    _touch(src / "b.py", "B = 2\n")                      # one file changes: all of them go
    assert _drop_stale_cache(src, cache)
    assert not any((cache / n).exists() for n in ours)
    assert all((cache / n).exists() for n in others)
    assert _drop_stale_cache(src, cache / "a.cpython-312.pyc" / "x")   # cannot be made: no error


def test_a_change_in_another_module_reaches_a_cached_kernel(tmp_path):
    # a copy of the package: block_partition (step.py) calls row_offsets (neighbours.py); after
    # row_offsets changes, a new process runs the new code, not the cached one
    pkg = tmp_path / "kcopy"
    shutil.copytree(os.path.dirname(dem.kernels.__file__), pkg,
                    ignore=shutil.ignore_patterns("__pycache__"))
    code = ("import numpy as np, kcopy; "
            "print(kcopy.block_partition(np.array([0, 0, 1, 2], np.int32), 4, 2)[1].tolist())")

    def run():
        env = dict(os.environ, PYTHONPATH=str(tmp_path))
        env.pop("NUMBA_CACHE_DIR", None)
        out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                             capture_output=True, text=True, check=True)
        return out.stdout.strip().splitlines()[-1]

    before = run()
    assert before == "[0, 3, 4]"        # pair offsets of the blocks [0, 2), [2, 4)
    assert any(n.startswith("step.block_partition") for n in os.listdir(pkg / "__pycache__"))
    nb = pkg / "neighbours.py"
    text = nb.read_text()
    assert text.count("off[pi[k] + 1] += 1") == 1
    nb.write_text(text.replace("off[pi[k] + 1] += 1", "off[pi[k] + 1] += 2"))
    assert run() == "[0, 4, 8]"      # the new row_offsets (blocks [0, 1), [1, 4)), not the cache
