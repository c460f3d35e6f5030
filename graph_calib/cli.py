"""The ``graph-calib`` command line: a thin layer over the public Python API.

Each command lives in its own module under :mod:`graph_calib.commands` with two
functions, ``add_arguments(parser)`` and ``run(args) -> int``.  Exit codes
(``cli.md``): 0 success, 2 bad input or arguments (one line, no traceback),
1 internal failure.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from graph_calib.errors import InputError

COMMANDS = {
    "simulate": "make a synthetic experiment or campaign",
    "import": "convert a bench or third-party log into an experiment file",
    "calibrate": "calibrate one experiment with one or both solvers",
    "campaign": "calibrate every experiment of a campaign and stitch over temperature",
    "diagnose": "the closed loop: residuals, the effect they point to, before and after",
    "demo": "simulate a navigation-grade campaign and run campaign and diagnose on it",
}


class _Parser(argparse.ArgumentParser):
    """argparse that exits with code 2 and one line on bad arguments (its default too, made explicit)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser():
    parser = _Parser(prog="graph-calib", description=__doc__.splitlines()[0])
    from graph_calib import __version__

    parser.add_argument("--version", action="version", version=f"graph-calib {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, help_text in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        module = _module(name)
        if module is not None:
            module.add_arguments(p)
        p.set_defaults(_module=name)
    return parser


def _module(name):
    try:
        return importlib.import_module(f"graph_calib.commands.{name.replace('-', '_')}_cmd")
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.startswith("graph_calib.commands"):
            return None
        raise


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    module = _module(args._module)
    if module is None:
        print(f"graph-calib {args.command}: not available in this version", file=sys.stderr)
        return 1
    try:
        return int(module.run(args) or 0)
    except InputError as exc:
        print(f"graph-calib {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"graph-calib {args.command}: interrupted; finished work is kept", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
