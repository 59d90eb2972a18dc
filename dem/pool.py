"""The DEM's runs over a pool of workers: the burst's staircases (``dem.burst``), the
directional analysis of saved states (``dem.probes``, ``dem.domain``), and the cross-check's DEM
stages together (``crosscheck.run``), each a generator of runs, all served by one set of
workers. A staircase is written as a
generator (``stairs.staircase_runs``) that asks for the runs of its chain one after another
(``yield Call(...)``: a relaxation, a hold of the staircase, whose result it waits for), starts
the runs that only need a state it already has beside it (``tasks.start(...)``: the relaxation
of the loaded peak, the below run and the baselines, the kinematic probe of every equilibrium),
and waits for those (``yield WAIT``) before its verdict. Two drivers run it:

* ``run_inline``: in this process, every run as it is asked for, the probes at the end (the
  staircase sets ``tasks.parallel`` False: the order of the runs, of the log and of the journal
  of a run on one worker, as before the pool);
* ``run_pool``: every run of every staircase as a task on ``workers`` local processes (spawned)
  or on a dask cluster (``scheduler``). The chain of each staircase goes first: a run it asks
  for is submitted at once, and the runs beside it take only the workers its chain leaves
  (``slots`` less the chains running): on two workers one runs the staircase, the other its
  probes. Runs that start others (the loaded peak's relaxation, the below run, the baselines)
  go before the probes, then first asked, first run. A run beside the staircase runs on one
  thread; the chain on ``threads`` (None: ``common.threads``'s choice, which stays on one
  thread while the other core is busy) when it is the only staircase on local processes, one
  thread otherwise.

Whatever finishes is handed back in the driver's own process (``done``: the journal, the log),
as it finishes; the results are kept by what they are (the journal's keys, the holds' indices),
never by the order they came in, so that the files are the same bits on one worker and on many.
On an interruption the runs that had finished are handed back (journaled) before the workers
are stopped."""
from __future__ import annotations

import heapq
import os
from typing import Any, Callable, NamedTuple


NEEDS_DASK = "--scheduler needs dask.distributed (pip install 'granular-w2[distributed]')"


class Call(NamedTuple):
    """A run of a staircase's chain: the generator waits for its result (``fn(*args,
    threads=..., **kwargs)``), handed first to ``done`` in the driver's process."""
    fn: Callable
    args: tuple
    kwargs: dict
    done: Callable | None = None


WAIT = "wait for the runs started beside the staircase"


def _run(fn, args, kwargs, threads):
    """A task of the pool (in a worker process or on a dask worker)."""
    return fn(*args, threads=threads, **kwargs)


class _InlineTasks:
    parallel = False

    def __init__(self, threads):
        self.threads = threads

    def start(self, fn, args, kwargs, done, first=False):
        res = fn(*args, threads=self.threads, **kwargs)
        if done:
            done(res)


def run_inline(make, threads=None):
    """The staircase generator ``make(tasks)`` run in this process, every run on ``threads``
    (None: ``common.threads``'s choice) as it is asked for; returns its result."""
    tasks = _InlineTasks(threads)
    gen = make(tasks)
    value = None
    while True:
        try:
            req = gen.send(value)
        except StopIteration as e:
            return e.value
        if req is WAIT:
            value = None
            continue
        value = req.fn(*req.args, threads=threads, **req.kwargs)
        if req.done:
            req.done(value)


class _Local:
    """``workers`` spawned processes (spawn, not fork: numba's OpenMP threading layer must not
    be forked)."""

    def __init__(self, workers):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        self.slots = workers
        self.ex = ProcessPoolExecutor(max_workers=workers,
                                      mp_context=multiprocessing.get_context("spawn"))

    def submit(self, fn, args, kwargs, threads, first):
        return self.ex.submit(_run, fn, args, kwargs, threads)

    def wait(self, futs):
        from concurrent.futures import FIRST_COMPLETED, wait
        return wait(list(futs), return_when=FIRST_COMPLETED).done

    @staticmethod
    def finished(fut):
        return fut.done() and not fut.cancelled() and fut.exception() is None

    def close(self, ok):
        if ok:
            self.ex.shutdown()
            return
        # Ctrl-C / SIGTERM (or a failed run): stop the workers now rather than wait for their
        # runs to end (the executor's exit would)
        for proc in list((getattr(self.ex, "_processes", None) or {}).values()):
            proc.terminate()
        self.ex.shutdown(wait=False, cancel_futures=True)


class _Dask:
    """The workers of the dask cluster at ``scheduler``: as many slots as they have threads; the
    chain's runs submitted at a higher priority."""

    def __init__(self, scheduler):
        try:
            from dask.distributed import Client
        except ImportError as e:
            raise RuntimeError(NEEDS_DASK) from e
        self.client = Client(scheduler)
        self.slots = max(1, sum(self.client.nthreads().values()))
        self.futs = []

    def submit(self, fn, args, kwargs, threads, first):
        f = self.client.submit(_run, fn, args, kwargs, threads, pure=False,
                               priority=1 if first else 0)
        self.futs.append(f)
        return f

    def wait(self, futs):
        from distributed import wait
        return wait(list(futs), return_when="FIRST_COMPLETED").done

    @staticmethod
    def finished(fut):
        return fut.status == "finished"

    def close(self, ok):
        if not ok:
            self.client.cancel([f for f in self.futs if not f.done()])
        self.client.close()


class _Owner:
    def __init__(self, tag):
        self.tag = tag
        self.gen = None
        self.side = 0            # runs started beside the chain, queued or running
        self.waiting = False     # at ``WAIT`` until they have all finished


class _PoolTasks:
    parallel = True

    def __init__(self, owner, start):
        self._owner, self._start = owner, start

    def start(self, fn, args, kwargs, done, first=False):
        self._start(self._owner, fn, args, kwargs, done, first)


def run_jobs(jobs, workers=None, scheduler=None, threads=None, chain_threads=None) -> dict:
    """The generators of ``jobs`` ([(tag, make)]): on one local worker (``workers`` 1, no
    ``scheduler``) each in this process, one after another (``run_inline``, every run on
    ``threads``); otherwise together over the pool (``run_pool``: the chains' runs on
    ``chain_threads``, the others on one thread). Returns {tag: the generator's result}."""
    if scheduler or (workers or os.cpu_count() or 1) > 1:
        return run_pool(jobs, workers, scheduler, None, chain_threads) if jobs else {}
    return {tag: run_inline(make, threads) for tag, make in jobs}


def run_pool(jobs, workers=None, scheduler=None, threads=None, chain_threads=None) -> dict:
    """The staircase generators of ``jobs`` ([(tag, make)], ``make(tasks)`` one generator) run
    over ``workers`` local processes (None: the cores) or the dask cluster at ``scheduler`` (see
    the module doc); ``threads``: of the runs beside the chains (1), ``chain_threads``: of the
    chains' runs. Returns {tag: the generator's result}."""
    backend = _Dask(scheduler) if scheduler else _Local(workers or os.cpu_count() or 1)
    owners, results = [], {}
    queue: list[tuple[int, int, Any]] = []      # (rank, order, (owner, fn, args, kwargs, done))
    running = {}                                 # future -> (owner, done, is the chain's)
    seq = [0]
    side_threads = 1 if threads is None else threads

    def start(owner, fn, args, kwargs, done, first):
        owner.side += 1
        seq[0] += 1
        heapq.heappush(queue, (0 if first else 1, seq[0], (owner, fn, args, kwargs, done)))

    def resume(o, value):
        while True:
            try:
                req = o.gen.send(value)
            except StopIteration as e:
                results[o.tag] = e.value
                return
            if req is WAIT:
                if o.side:
                    o.waiting = True
                    return
                value = None
                continue
            fut = backend.submit(req.fn, req.args, req.kwargs, chain_threads, True)
            running[fut] = (o, req.done, True)
            return

    def fill():
        chains = sum(1 for v in running.values() if v[2])
        sides = len(running) - chains
        while queue and sides < backend.slots - chains:
            _, _, (o, fn, args, kwargs, done) = heapq.heappop(queue)
            running[backend.submit(fn, args, kwargs, side_threads, False)] = (o, done, False)
            sides += 1

    ok = False
    try:
        for tag, make in jobs:
            o = _Owner(tag)
            o.gen = make(_PoolTasks(o, start))
            owners.append(o)
            resume(o, None)
        fill()
        while running:
            for fut in backend.wait(running):
                o, done, chain = running.pop(fut)
                res = fut.result()
                if done:
                    done(res)
                if chain:
                    resume(o, res)
                else:
                    o.side -= 1
                    if o.waiting and not o.side:
                        o.waiting = False
                        resume(o, None)
            fill()
        ok = True
    except BaseException:
        # what had finished is handed back (journaled: a resume does not run it again)
        for fut, (o, done, _) in list(running.items()):
            try:
                if done and backend.finished(fut):
                    done(fut.result())
            except BaseException:       # noqa: BLE001 - the first error is the one to raise
                pass
        raise
    finally:
        backend.close(ok)
    return results
