"""Interrupting a command line in a subprocess (the CLIs' Ctrl-C / SIGTERM tests).

No test waits a fixed delay: the signal goes when the run has printed the line that marks the
point that matters (and, if the test says so, once a condition it polls holds: a file the run
writes), and every interrupted run is made far longer than it needs to be, so that it cannot end
by itself in between on any machine (a run that the signal cuts short costs nothing). What the
tests assert then does not depend on the machine's speed."""
import signal
import subprocess
import sys
import threading
import time


# a hang guard, not a timing assertion: far beyond any run here, first compilation included,
# on a busy machine
HANG_S = 600


def interrupt_after(argv, first, sig=signal.SIGTERM, timeout=HANG_S, until=None):
    """Run ``python -m argv...`` and send ``sig`` once a stderr line starts with ``first`` and,
    if ``until`` is given, once ``until()`` is true (polled every 20 ms after that line);
    returns (exit code, stderr lines printed after that line). AssertionError if the run ends
    or ``timeout`` seconds pass before that point (a hang, not a timing assertion)."""
    # a test run started in the background of a non-interactive shell inherits SIGINT ignored,
    # and Python then never raises KeyboardInterrupt: give the child the default disposition,
    # as a terminal would
    p = subprocess.Popen([sys.executable, "-m", *argv], stderr=subprocess.PIPE,
                         stdout=subprocess.DEVNULL, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen = threading.Event()
    before, after = [], []

    def read():       # drains stderr all along, so that the child never blocks on a full pipe
        for line in p.stderr:
            (after if seen.is_set() else before).append(line)
            if not seen.is_set() and line.startswith(first):
                seen.set()
        seen.set()    # the run ended (the check below tells)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + timeout
        seen.wait(timeout)
        assert p.poll() is None and before and before[-1].startswith(first), (
            f"the run never printed a line starting with {first!r}: {''.join(before)[-2000:]}")
        while until is not None and not until():
            assert p.poll() is None, f"the run ended before the point the test waits for: " \
                                     f"{''.join(before + after)[-2000:]}"
            assert time.monotonic() < deadline, "the point the test waits for never came"
            time.sleep(0.02)
        p.send_signal(sig)
        p.wait(timeout=timeout)
        reader.join(timeout)
    finally:
        p.kill()
    return p.returncode, "".join(after).strip().splitlines()
