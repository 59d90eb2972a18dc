"""Command line: ``python -m hmodel {biaxial,probes,domain,burst,fit,params} ...``: the commands
of the material point of any law (``point.cli``) with the H-model as their one law: its options
(``hmodel.params``: --params FILE, --kn, --phi-g, ...), Table I its defaults. The files of fit,
probes and domain are written by ``write_fit``, ``write_probes`` and ``write_domain`` from an
HParams record and the library's results, so that a caller with its own record (``python -m
crosscheck.fit``) writes the same folders without an argv."""
from __future__ import annotations

from functools import partial

from point import cli as _cli
from point.contract import material_named

from . import plots  # noqa: F401  (hmodel.plots is point.plots: the figures of these commands)

PROG = "python -m hmodel"
DESCRIPTION = """The H-microdirectional model as a material point (Nicot, Hadda & Darve 2013).
python -m hmodel COMMAND --help lists a command's options, each with its unit and default.
--out is required: a folder (the parameter file for params) that records the command that wrote
it (command.json); another command refuses that folder unless --force."""

write_probes = partial(_cli.write_probes, command=f"{PROG} probes")
write_domain = partial(_cli.write_domain, command=f"{PROG} domain")
write_domain_rows = partial(_cli.write_domain_rows, command=f"{PROG} domain")
write_fit = _cli.write_fit


def build_parser():
    """The parser of ``python -m hmodel``: ``point.cli.build_parser`` of the H-model."""
    return _cli.build_parser(PROG, material_named("hmodel"), DESCRIPTION)


def main(argv=None) -> int:
    """``python -m hmodel ...``: ``point.cli.main`` of the H-model (0 done, 1 not fittable or a
    Newton failure where a static state exists, 2 bad option or a broken law, 130 / 143
    interrupted)."""
    return _cli.main(argv, PROG, material_named("hmodel"), DESCRIPTION)
