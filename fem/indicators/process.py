"""The global check in a process of its own (``GlobalCheckProcess``, forked at the first step),
so that a biaxial run on more than one core does its local indicators and its output while the
stiffness of the step is checked."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .global_check import GlobalCheck

__all__ = ["GlobalCheckProcess"]


class GlobalCheckProcess:
    """``GlobalCheck`` of ``problem`` in a child process, for a run on more than one core: the
    run ``submit``s the stiffness of a converged step and does its local indicators and the
    previous step's output while the child checks it, then takes the ``result``. The child
    checks the steps one after another in their order with one GlobalCheck, so every row and
    mode is the same to the bit as in process.

    The child is forked at the first ``submit``: it shares the problem, the compiled kernels
    and that stiffness's sparsity pattern, and K.data goes through a shared buffer (the
    pattern is the same at every step of a run: only a one-byte message goes through the
    pipe; a new pattern goes whole). It runs no parallel kernel, so it needs none of the
    parent's threads. ``start`` returns None where fork is not available. The child ignores
    SIGINT and SIGTERM (Ctrl-C reaches the whole process group: the parent decides) and ends
    when the parent closes the pipe, or dies (the kernel closes it then)."""

    def __init__(self, problem, seed: int):
        self._problem, self._seed = problem, seed
        self._conn = self._proc = None
        self._pattern = self._buf = None

    @classmethod
    def start(cls, problem, seed: int = 0):
        import multiprocessing
        if "fork" not in multiprocessing.get_all_start_methods():
            return None
        return cls(problem, seed)

    def _fork(self, K):
        import mmap
        import multiprocessing
        import sys
        import warnings
        ctx = multiprocessing.get_context("fork")
        self._pattern = (K.indptr.copy(), K.indices.copy(), K.shape)
        self._buf = np.frombuffer(mmap.mmap(-1, max(K.data.nbytes, 8)), dtype=float)[:K.nnz]
        sys.stdout.flush()      # else the child would write the parent's buffered lines again
        sys.stderr.flush()
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_check_server,
                           args=(child, parent, self._problem, self._seed, self._pattern,
                                 self._buf), daemon=True, name="fem-global-check")
        with warnings.catch_warnings():
            # Python >= 3.12 warns about fork in a process with threads (Numba's pool): the
            # child runs only single-threaded code and takes no lock those threads hold
            warnings.simplefilter("ignore", DeprecationWarning)
            proc.start()
        child.close()
        self._conn, self._proc = parent, proc

    def submit(self, K, want_modes: bool = True) -> None:
        """Start the check of K (the previous one must have been taken by ``result``)."""
        K = sp.csr_matrix(K)
        if self._proc is None:
            self._fork(K)
        indptr, indices, shape = self._pattern
        if K.shape == shape and np.array_equal(K.indptr, indptr) \
                and np.array_equal(K.indices, indices):
            self._buf[:] = K.data
            self._conn.send_bytes(b"M" if want_modes else b"m")
        else:
            self._conn.send((K.indptr, K.indices, K.data, K.shape, want_modes))

    def result(self) -> tuple[dict, dict]:
        try:
            kind, value = self._conn.recv()
        except EOFError:
            raise RuntimeError(f"the global check's process ended (exit code "
                               f"{self._proc.exitcode})") from None
        if kind == "error":
            raise value
        return value

    def close(self) -> None:
        if self._proc is None:
            return
        try:
            self._conn.close()
        finally:
            self._proc.join(timeout=5)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join()
            self._proc = None


def _check_server(conn, parent_end, problem, seed, pattern, buf):
    """The child of GlobalCheckProcess: one GlobalCheck, a step at a time, until the parent
    closes the pipe. A one-byte message: K has ``pattern`` and its data in ``buf`` (shared)."""
    import pickle
    import signal
    parent_end.close()      # the fork copied it: held open here, it would hide the parent's EOF
    for sig in (signal.SIGINT, signal.SIGTERM):     # the parent's to handle; it closes the pipe
        signal.signal(sig, signal.SIG_IGN)
    check = GlobalCheck(problem, seed=seed)
    indptr, indices, shape = pattern
    while True:
        try:
            msg = conn.recv_bytes()
        except (EOFError, OSError):
            return
        if len(msg) == 1:
            K = sp.csr_matrix((buf.copy(), indices, indptr), shape=shape)
            want_modes = msg == b"M"
        else:
            indptr_k, indices_k, data, shape_k, want_modes = pickle.loads(msg)
            K = sp.csr_matrix((data, indices_k, indptr_k), shape=shape_k)
        try:
            out = ("ok", check(K, want_modes))
        except Exception as e:          # to the parent, which raises it
            out = ("error", e)
        try:
            try:
                conn.send(out)
            except (pickle.PicklingError, TypeError, AttributeError):    # an unpicklable error
                conn.send(("error", RuntimeError(f"in the global check's process: {out[1]!r}")))
        except (BrokenPipeError, OSError):    # the parent stopped waiting (its run ended)
            return
