"""How many threads a run uses: a fixed count, or ``auto`` (the default); the one thread
chooser of the project (``ThreadChooser``): dem's simulation steps and fem's local indicators.

The rule of both: more threads never make a run much slower than one.  Only measured wall
times decide between 1 and all threads, the slower choice is re-tried now and then (the load of
a shared machine moves), and the first call of each is not a measure (it loads the kernels).
The results do not depend on the choice (the same bits for any thread count).  Two ways to pace
the re-trials, for two kinds of work:

* a run of many steps that can be cut into chunks (dem: ``next(left)`` gives the thread count
  and the chunk, ``record(threads, units, seconds)`` its measure): by the clock, as follows;
* a kernel called whole, many times (fem's local indicators, a step of a biaxial run:
  ``pick(n_max)`` and ``record(threads, seconds_per_unit)``): the faster by the running mean of
  its time per unit of work, the slower re-tried every ``retry`` calls.

By the clock (dem):

The kernel gives the same bits for any number of disk blocks (``kernels._block_step``), so the
thread count is a pure speed choice and may change between two calls of ``kernels.advance``.
Two threads pay two barriers per step; on a 2-core machine where another process keeps a core
busy, a barrier waits for the OS to schedule the other thread, ~5-20 ms a step (measured: a
300-disk biaxial test went from 5.5 s on one thread to more than 300 s on two).  Whether more
threads help therefore depends on the sample size *and* on what else the machine does, which
can change during a run.  ``auto``:

* one thread below ``SERIAL_BELOW`` disks (a step is too short for the barriers to pay);
* above, it times every ``advance`` call (wall clock, particle-steps per second) and runs with
  whichever of 1 and ``max_threads`` thread(s) is faster, re-trying the slower choice in a short
  chunk (``TRIAL_STEPS``) after ``RETRY_S`` seconds, the interval doubling (to ``RETRY_MAX_S``)
  each time the trial loses.  The first chunk of each count is not measured (it loads the
  kernels and wakes the thread pool: a cold 3-step chunk measured 15 times too slow).  Once
  all threads have won a trial they run chunks of ``2 TRIAL_STEPS`` steps, doubling while
  they stay faster, and not whole chunks to the next neighbour rebuild at once: a 3-step trial
  can win by chance while a busy process takes the other core, and a 640-step chunk at the 12x
  slowdown of two threads then cost 4 s (measured: auto at 0.24x one thread over a
  2000-step run).  The cost of a wrong choice is thus bounded by a few tenths of a second per
  retry interval, so a run is never much slower than on one thread, however the load moves.

The figures behind the constants are printed by ``python bench/bench_dem.py`` (one thread
against ``auto`` at 300, 2000 and 12,000 disks, alone and beside a busy process).
"""
from __future__ import annotations

import os
import time

import numba

SERIAL_BELOW = 1000     # disks: below, one thread (two barriers a step cost more than they save)
TRIAL_STEPS = 3         # steps of a trial chunk (a losing trial costs at most ~3 x 20 ms)
RETRY_S = 5.0           # first retry interval [s] of the losing choice
RETRY_MAX_S = 120.0     # cap of the doubling retry interval [s]

_default = None         # None = auto; an int = fixed count (set_default_threads)


def available_threads() -> int:
    """Threads Numba may use here: its pool size, capped by the cores this process may run on."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(numba.config.NUMBA_NUM_THREADS, cores))


def check_threads(threads, option="--threads"):
    """ValueError unless ``threads`` is None (auto) or an int in [1, available_threads()]."""
    if threads is None:
        return None
    hi = available_threads()
    if isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads <= hi:
        raise ValueError(f"{option}={threads!r}; allowed range: 1 <= {option.lstrip('-')} <= {hi} "
                         "(the cores this process may use), or omit it for auto")
    return threads


def set_default_threads(threads):
    """Thread count of every Simulation that does not set its own: None = auto, or an int."""
    global _default
    _default = check_threads(threads)


class ThreadChooser:
    """Chooses the thread count of each call (see the module docstring).

    ``ThreadChooser(n_disks, threads)`` (paced by the clock, dem): ``threads`` a fixed count,
    None the default (``set_default_threads``: auto unless set); ``next(left)`` and
    ``record(threads, units, seconds)``.  Only measured rates decide: the current choice runs
    full chunks; the other one runs a ``TRIAL_STEPS`` chunk when its retry time has come (or at
    once, when the current choice has become slower than the other's last measurement), and
    takes over only if that trial is faster.

    ``ThreadChooser(retry=k)`` (paced by calls, fem's local indicators: always auto, whatever the
    default): ``pick(n_max)`` the count of the next call among 1 and ``n_max``, and
    ``record(threads, seconds_per_unit)``; each count is tried once after an untimed first call,
    then the faster by the running mean of its time per unit, the slower re-tried every ``k``
    calls."""

    def __init__(self, n_disks: int | None = None, threads=None, retry: int | None = None):
        self.retry = retry          # None: re-trials paced by the clock; k: every k calls
        if retry is None:
            threads = _default if threads is None else threads
        self.fixed = check_threads(threads) if threads is not None else None
        self.max_threads = available_threads()
        self.adaptive = (self.fixed is None and (n_disks is None or n_disks >= SERIAL_BELOW)
                         and self.max_threads > 1)
        self.current = self.fixed or 1
        self.rate = {}              # threads -> last measured units/s (by the clock)
        self.retry_at = {}          # threads -> wall time of its next trial
        self.retry_s = {}           # threads -> current retry interval [s]
        self.trials = 0             # trial chunks run (reported by the bench)
        self.warm = set()           # thread counts whose first (unmeasured) call has run
        self.span = 2 * TRIAL_STEPS  # steps of the next chunk on all threads (doubles)
        self.t = {}                 # threads -> running mean of seconds per unit (by calls)
        self.calls = 0              # calls since both counts were measured (by calls)

    def _other(self, k):
        return self.max_threads if k == 1 else 1

    def next(self, left: int):
        """(threads, steps to run at most) for the next ``advance`` call."""
        if not self.adaptive:
            return self.current, left
        for k in (1, self.max_threads):
            if k not in self.rate:                      # warm up, then measure both first
                return k, min(left, TRIAL_STEPS)
        other = self._other(self.current)
        if time.perf_counter() >= self.retry_at.get(other, 0.0):
            return other, min(left, TRIAL_STEPS)
        if self.current != 1:
            return self.current, min(left, self.span)
        return self.current, left

    def pick(self, n_max: int) -> int:
        """The thread count of the next call, among 1 and ``n_max`` (paced by calls)."""
        if self.fixed is not None:
            return min(self.fixed, n_max)
        if n_max <= 1:
            return 1
        for n in (1, n_max):
            if n not in self.t:
                return n
        self.calls += 1
        best, other = sorted((1, n_max), key=self.t.get)
        return other if self.calls % self.retry == 0 else best

    def record(self, threads: int, units, seconds=None):
        """The measure of the call just run with ``threads`` threads: ``units`` of work (steps
        x disks) in ``seconds`` (by the clock), or (paced by calls) ``units`` the seconds per
        unit of work."""
        if self.retry is not None:
            self._record_per_unit(threads, units)
            return
        particle_steps = units
        if not self.adaptive or particle_steps <= 0:
            return
        if threads not in self.warm:                       # warm-up chunk: not a measure
            self.warm.add(threads)
            self.trials += 1
            return
        self.rate[threads] = particle_steps / max(seconds, 1e-9)
        now = time.perf_counter()
        if len(self.rate) < 2:
            self.trials += 1
            return
        if threads != self.current:                        # a trial chunk
            self.trials += 1
            if self.rate[threads] > self.rate[self._other(threads)]:
                self.current = threads
                self.span = 2 * TRIAL_STEPS
                self.retry_s[self._other(threads)] = RETRY_S
            else:                                          # it lost: wait longer next time
                self.retry_s[threads] = min(2 * self.retry_s.get(threads, RETRY_S / 2),
                                            RETRY_MAX_S)
            other = self._other(self.current)
            self.retry_at[other] = now + self.retry_s.setdefault(other, RETRY_S)
        elif self.rate[threads] < self.rate[self._other(threads)]:
            # the current choice got slower than the other's last measurement (the load
            # changed): try the other one now rather than switch on an old figure
            self.retry_at[self._other(threads)] = now
        elif threads != 1:
            self.span *= 2                                 # all threads confirmed: longer chunks

    def _record_per_unit(self, threads: int, seconds_per_unit: float) -> None:
        if not self.warm:                # the first call loads the compiled kernels: not timed
            self.warm.add(threads)
            return
        old = self.t.get(threads)
        self.t[threads] = seconds_per_unit if old is None else 0.5 * (old + seconds_per_unit)
