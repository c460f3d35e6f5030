"""The ``graph-calib`` command line: a thin layer over the public Python API.

Each command lives in its own module under :mod:`graph_calib.commands` with two
functions, ``add_arguments(parser)`` and ``run(args) -> int``.  Exit codes
(``cli.md``): 0 success, 2 bad input or arguments (one line, no traceback),
1 internal failure (one line naming the command and the exception; with the
environment variable ``GRAPH_CALIB_DEBUG=1`` the exception is re-raised, traceback
included), 3 when the work finished but its verdict failed (a solver did not
converge, the solvers disagree, or the residuals do not fit the noise model; every
file is still written), 130 when interrupted.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys

from graph_calib.errors import InputError

COMMANDS = {
    "simulate": "make a synthetic experiment or campaign",
    "import": "convert a bench or third-party log into an experiment file",
    "calibrate": "calibrate one experiment with one or both solvers",
    "predict": "predicted accuracy of an experiment's calibration (Fisher information, no solver run)",
    "design": "the shortest bench program whose predicted accuracy meets the targets (CasADi)",
    "campaign": "calibrate every experiment of a campaign and stitch over temperature",
    "diagnose": "the closed loop: residuals, the effect they point to, before and after",
    "apply": "correct a raw record with a result, a compensation table or a campaign's stitched calibration",
    "export": "write a campaign's stitched calibration as a compensation table (JSON, CSV, C header)",
    "demo": "simulate a navigation-grade campaign and run campaign and diagnose on it",
}


class _Parser(argparse.ArgumentParser):
    """argparse that exits with code 2 and one line on bad arguments (its default too, made explicit)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser(only=None):
    """The command-line parser; with ``only`` (a command name) only that command's arguments are added.

    Each command's module is imported to add its arguments; ``main`` asks for the one
    command being run, so that ``graph-calib calibrate`` does not import what
    ``campaign``, ``diagnose`` or ``apply`` need (scipy.stats among them: most of the
    start-up, docs/performance.md).  ``graph-calib --help`` lists every command.
    """
    parser = _Parser(prog="graph-calib", description=__doc__.splitlines()[0])
    from graph_calib import __version__

    parser.add_argument("--version", action="version", version=f"graph-calib {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, help_text in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if only is None or name == only:
            _module(name).add_arguments(p)
    return parser


def _module(name):
    """The module of command ``name``: ``graph_calib.commands.<name>_cmd``."""
    return importlib.import_module(f"graph_calib.commands.{name.replace('-', '_')}_cmd")


def _debug():
    return os.environ.get("GRAPH_CALIB_DEBUG", "") not in ("", "0")


def _command_named(argv):
    """The command that ``argv`` runs (its first word that is not an option), or None."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in COMMANDS else None
    return None


def main(argv=None):
    """Run the command ``argv`` (default: the command line); its exit code (cli.md).

    With ``argv`` None (the ``graph-calib`` script, ``python -m graph_calib.cli``) the process ends after
    it, and every object is first frozen for the garbage collector (``gc.freeze``): the interpreter's
    final collections then skip the many objects numba, scipy and gtsam made (docs/performance.md has the
    figure).  Files are written and closed explicitly before;
    nothing waits for the collector.  Called with ``argv`` (the tests, other Python code), nothing is frozen.
    """
    code = _main(sys.argv[1:] if argv is None else list(argv))
    if argv is None:
        gc.freeze()
    return code


def _main(argv):
    parser = build_parser(only=_command_named(argv))
    args = parser.parse_args(argv)
    try:
        return int(_module(args.command).run(args) or 0)
    except InputError as exc:
        print(f"graph-calib {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"graph-calib {args.command}: interrupted; finished work is kept", file=sys.stderr)
        return 130
    except Exception as exc:
        if _debug():
            raise
        print(f"graph-calib {args.command}: internal error: {_one_line(exc)} "
              "(GRAPH_CALIB_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1


def _one_line(exc):
    """``RuntimeError: boom``: the exception's type and the first line of its message."""
    lines = str(exc).strip().splitlines()
    if not lines:
        return type(exc).__name__
    return f"{type(exc).__name__}: {lines[0]}" + (" ..." if len(lines) > 1 else "")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
