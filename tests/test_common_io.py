"""The atomic writers of ``common.io`` (issue 33): the file gets the mode an ordinary new file
gets under the umask (without the process ever setting it: two threads writing at once both get
it), and an interrupted write leaves the previous file as it was, and no temporary file."""
import os
import stat
import threading

import numpy as np
import pytest

from common.io import REPR, atomic_open, atomic_path, atomic_write_bytes, file_mode, write_csv


def _mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_the_file_gets_the_mode_of_the_umask(tmp_path, umask):
    old = os.umask(umask)          # the test sets it (as a shell would); the writer never does
    try:
        assert file_mode() == 0o666 & ~umask
        atomic_write_bytes(tmp_path / "a.bin", b"x")
        with atomic_open(tmp_path / "b.txt") as f:
            f.write("y")
        with atomic_path(tmp_path / "c.vtu") as tmp:
            with open(tmp, "w") as f:
                f.write("z")
        write_csv(tmp_path / "d.csv", {"x": [1.0]})
        write_csv(tmp_path / "e.csv", ["x"], [[1.0]], fmt=REPR)
    finally:
        os.umask(old)
    for f in ("a.bin", "b.txt", "c.vtu", "d.csv", "e.csv"):
        assert _mode(tmp_path / f) == 0o666 & ~umask, f
    assert sorted(os.listdir(tmp_path)) == ["a.bin", "b.txt", "c.vtu", "d.csv", "e.csv"]


def test_two_threads_writing_at_once_both_get_the_mode(tmp_path):
    """Writers in two threads, many files each, while the umask stays what it is: every file
    gets 0666 less it (a writer that set the umask for a moment to read it would give a file of
    the other thread mode 0666 now and then)."""
    want = file_mode()
    errors = []

    def work(k):
        try:
            for i in range(200):
                atomic_write_bytes(tmp_path / f"t{k}_{i}.bin", b"data")
                fd = os.open(tmp_path / f"plain{k}_{i}", os.O_WRONLY | os.O_CREAT, 0o666)
                os.close(fd)
        except Exception as e:       # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    modes = {f: _mode(tmp_path / f) for f in os.listdir(tmp_path)}
    assert len(modes) == 800
    assert {m for m in modes.values()} == {want}


def test_an_interrupted_write_leaves_the_previous_file(tmp_path):
    path = tmp_path / "out.csv"
    atomic_write_bytes(path, b"before\n")
    with pytest.raises(KeyboardInterrupt):
        with atomic_open(path, "wb") as f:
            f.write(b"half of the new")
            raise KeyboardInterrupt
    assert path.read_bytes() == b"before\n"
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            with open(tmp, "w") as f:
                f.write("half")
            raise RuntimeError("killed")
    assert path.read_bytes() == b"before\n"
    with pytest.raises(ValueError):      # a row that cannot be written: nothing replaced
        write_csv(path, {"a": [1.0, 2.0], "b": [1.0]})
    assert path.read_bytes() == b"before\n"
    assert os.listdir(tmp_path) == ["out.csv"]       # no temporary file left


def test_the_one_csv_writer_keeps_each_callers_number_format(tmp_path):
    """The H-model's, fem's and the cross-check's files: 10 significant digits, booleans 0/1, a
    missing value "nan" (or an empty field); dem's tables: every float to the bit (repr), other
    values as the csv module writes them (as dem.io wrote them before)."""
    x = [0.1 + 0.2, 1e-20 / 3, True, np.float64(2.5), 7, float("nan")]
    write_csv(tmp_path / "g.csv", {"x": x})
    assert (tmp_path / "g.csv").read_text().split("\n") == [
        "x", "0.3", "3.333333333e-21", "1", "2.5", "7", "nan", ""]
    write_csv(tmp_path / "t.csv", {"x": [float("nan"), 1.0], "s": ["a", "b"]}, nan="")
    assert (tmp_path / "t.csv").read_text() == "x,s\n,a\n1,b\n"
    write_csv(tmp_path / "r.csv", ["x", "n", "b", "s"],
              [[0.1 + 0.2, 7, True, "a,b"], [np.float64(1e-20 / 3), np.int64(3), None, "c"]], fmt=REPR)
    assert (tmp_path / "r.csv").read_text() == (
        f"x,n,b,s\n0.30000000000000004,7,True,\"a,b\"\n{1e-20 / 3!r},3,,c\n")
