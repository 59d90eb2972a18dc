"""Running a command line in-process for the bad-input tests: ``python -m dem ARGV``, or
``python -m crosscheck ARGV[1:]`` for ``["crosscheck", ...]`` (``python -m dem crosscheck`` until
issue 33, now a command of its own above the three parts: the same options and rules)."""
import pytest


def run_dem(argv, capsys):
    """-> (exit code, stderr lines) of ``python -m dem ARGV`` (or of ``python -m crosscheck``)."""
    if argv[0] == "crosscheck":
        from crosscheck.__main__ import main as crosscheck_main
        code = crosscheck_main(argv[1:])
    else:
        from dem.__main__ import main
        with pytest.raises(SystemExit) as e:
            main(argv)
        code = e.value.code
    return code, capsys.readouterr().err.strip().splitlines()
