"""The thread chooser (``common.threads``, issue 10/11): with simulated chunk timings on a fake
clock, ``auto`` keeps what is faster, and a lucky trial of the slower choice costs a bounded
number of steps, never a whole chunk to the next rebuild."""

import common.threads as T


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def drive(monkeypatch, seconds_per_step, steps=20_000, chunk=640, lucky=()):
    """Run ``steps`` steps through a ThreadChooser(2 threads), each advance call at most
    ``chunk`` steps (the next rebuild); ``seconds_per_step(threads, call)`` is the cost;
    calls listed in ``lucky`` run on their thread count at the other one's speed (a trial
    that wins by chance).  Returns (wall time, steps run per thread count, chooser)."""
    clock = Clock()
    monkeypatch.setattr(T.time, "perf_counter", clock)
    monkeypatch.setattr(T, "available_threads", lambda: 2)
    monkeypatch.setattr(T, "_default", None)      # auto, whatever an earlier test set
    ch = T.ThreadChooser(12_000, None)
    assert ch.adaptive
    left, call, per = steps, 0, {1: 0, 2: 0}
    while left > 0:
        th, n = ch.next(left)
        n = min(n, chunk)
        cost = seconds_per_step(3 - th if call in lucky else th, call) * n
        clock.t += cost
        ch.record(th, n * 12_000, cost)
        per[th] += n
        left -= n
        call += 1
    return clock.t, per, ch


def test_busy_core_a_lucky_two_thread_trial_costs_a_few_steps(monkeypatch):
    # another process on the other core: two threads 12 x slower; the first measured trial of
    # two threads (call 3, after the two warm-up chunks and the one-thread measure) wins by luck
    slow = lambda th, call: 3e-4 if th == 1 else 12 * 3e-4
    t, per, ch = drive(monkeypatch, slow, lucky=(3,))
    one = 20_000 * 3e-4
    assert per[2] <= 3 * T.TRIAL_STEPS + 2 * T.TRIAL_STEPS     # trials + one short chunk
    assert t < 1.05 * one                                       # never much slower than 1 thread


def test_idle_machine_two_threads_win_and_run_long_chunks(monkeypatch):
    fast = lambda th, call: 3e-4 if th == 1 else 3e-4 / 1.8
    t, per, ch = drive(monkeypatch, fast)
    assert ch.current == 2 and per[2] > 0.95 * 20_000
    assert t < 1.02 * 20_000 * 3e-4 / 1.8


def test_the_first_chunk_of_each_count_is_not_a_measure(monkeypatch):
    # a cold first chunk (kernel load, thread pool wake-up) 15 x slower must not decide
    cold = lambda th, call: (15 if call == 0 else 1) * (3e-4 if th == 1 else 12 * 3e-4)
    t, per, ch = drive(monkeypatch, cold)
    assert ch.current == 1 and t < 1.05 * 20_000 * 3e-4 + 15 * 3e-4 * T.TRIAL_STEPS
