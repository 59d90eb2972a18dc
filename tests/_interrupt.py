"""Interrupting a command line in a subprocess (the CLIs' Ctrl-C / SIGTERM tests)."""
import signal
import subprocess
import sys
import time


def interrupt_after(argv, first, sig=signal.SIGTERM, timeout=60, delay=0.0):
    """Run ``python -m argv...``, send ``sig`` once a stderr line starts with ``first`` (and
    ``delay`` seconds more); returns (exit code, stderr lines printed after that line)."""
    # a test run started in the background of a non-interactive shell inherits SIGINT ignored,
    # and Python then never raises KeyboardInterrupt: give the child the default disposition,
    # as a terminal would
    p = subprocess.Popen([sys.executable, "-m", *argv], stderr=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        for line in p.stderr:
            if line.startswith(first):
                break
        time.sleep(delay)
        p.send_signal(sig)
        _, err = p.communicate(timeout=timeout)
    finally:
        p.kill()
    return p.returncode, err.strip().splitlines()
