"""The ``graph-calib`` command line: a thin layer over the public Python API.

A bare ``graph-calib`` and ``graph-calib --help`` print :func:`overview`: the commands
with an example each and the exit codes.  Every command's ``--out`` is checked before
any work starts (:data:`OUTPUTS`), and a reader closing the pipe (``graph-calib ... |
head``) drops the rest of the output without stopping the work.

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
    "compare": "campaign procedures (steps, ramps, programs) on predicted accuracy against duration; HTML report",
    "campaign": "calibrate every experiment of a campaign and stitch over temperature",
    "diagnose": "the closed loop: residuals, the effect they point to, before and after",
    "crossval": "calibrate without each fold of a record's poses and judge on the held-out ones",
    "apply": "correct a raw record with a result, a compensation table or a campaign's stitched calibration",
    "export": "write a calibration for a navigation system: a compensation table (JSON, CSV, C header) or the "
              "ecosystem's files (PX4, ArduPilot, Kalibr, OpenVINS)",
    "demo": "simulate a navigation-grade campaign and run campaign and diagnose on it",
}

#: One example per command, shown by a bare ``graph-calib`` and ``graph-calib --help``.
EXAMPLES = {
    "simulate": "graph-calib simulate nav-subrange-short --out sim --seed 1",
    "import": "graph-calib import rosbag my_bag --latitude-deg 48.1 --out session.h5",
    "calibrate": "graph-calib calibrate sim/sub1_20_25.h5 --out cal",
    "predict": "graph-calib predict sim/sub1_20_25.h5 --out prediction.json",
    "design": "graph-calib design --out design",
    "campaign": "graph-calib campaign sim/campaign.toml --out camp",
    "diagnose": "graph-calib diagnose session.h5 --out diag",
    "crossval": "graph-calib crossval session.h5 --out cv --by transitions",
    "compare": "graph-calib compare data/programs/procedure-steps.toml data/programs/procedure-ramp.toml --out cmp",
    "apply": "graph-calib apply cal/factor-graph.json session.h5 --out corrected.h5",
    "export": "graph-calib export camp --format px4 --out thermal.params",
    "demo": "graph-calib demo --out demo",
}

#: What each command's ``--out`` names: checked before any work starts (exit 2), in every command.
OUTPUTS = {"simulate": "folder", "import": "file", "calibrate": "folder", "predict": "file", "design": "folder",
           "campaign": "folder", "diagnose": "folder", "crossval": "folder", "compare": "folder", "apply": "file", "export": "file", "demo": "folder"}

EXIT_CODES = {0: "success", 2: "bad input or arguments (one line naming the file, dataset or option)",
              3: "the work finished but its verdict failed (not converged, solvers disagree, residuals inconsistent; "
                 "every file is still written)",
              1: "internal failure (GRAPH_CALIB_DEBUG=1 shows the traceback)", 130: "interrupted"}


def overview():
    """The text of a bare ``graph-calib`` and of ``graph-calib --help``: the commands, an example each, exit codes."""
    from graph_calib import __version__
    from graph_calib.importers.registry import formats

    lines = [f"graph-calib {__version__}: thermal calibration of IMUs (one model; a GTSAM factor graph and a "
             "square-root Kalman filter)", "",
             "usage: graph-calib COMMAND [options]   (graph-calib COMMAND --help: its options)", "", "commands:"]
    for name, text in COMMANDS.items():
        lines += [f"  {name:<10} {text}", f"  {'':<10}   e.g. {EXAMPLES[name]}"]
    lines += ["", f"import formats: {', '.join(formats())}", "", "exit codes:"]
    lines += [f"  {code:<4} {text}" for code, text in EXIT_CODES.items()]
    return "\n".join(lines) + "\n"


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
    if argv is None:
        # both streams: ``graph-calib ... 2>&1 | head`` closes the pipe the progress and verdict lines go to as well
        sys.stdout, sys.stderr = _PipeSafe(sys.stdout), _PipeSafe(sys.stderr)
    code = _main(sys.argv[1:] if argv is None else list(argv))
    if argv is None:
        gc.freeze()
    return code


class _PipeSafe:
    """stdout (or stderr) that survives a reader closing the pipe (``graph-calib ... | head``): the work goes on, the files are
    written, the rest of the output is dropped (fd 1 is pointed at /dev/null so that no later flush fails)."""

    def __init__(self, stream):
        self._stream = stream
        self.lost = False

    def _lose(self):
        self.lost = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
        except (OSError, ValueError):
            pass

    def write(self, text):
        if not self.lost:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._lose()
        return len(text)

    def flush(self):
        if not self.lost:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._lose()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _check_output(command, args):
    """The command's ``--out`` checked before any work (commands/paths.py): exit 2 rather than a failure after it."""
    from graph_calib.commands.paths import output_file, output_folder

    out = getattr(args, "out", None)
    kind = OUTPUTS.get(command)
    if out is None or kind is None:
        return
    (output_folder if kind == "folder" else output_file)(out)


def _main(argv):
    if not argv or argv[0] in ("-h", "--help"):
        print(overview(), end="")
        return 0 if argv else 2
    parser = build_parser(only=_command_named(argv))
    args = parser.parse_args(argv)
    try:
        _check_output(args.command, args)
        return int(_module(args.command).run(args) or 0)
    except InputError as exc:
        print(f"graph-calib {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:      # a reader closed the pipe before stdout was made safe: not an internal error
        return 141
    except MemoryError as exc:   # an input that asks for more than the machine has (a program of 1e9 s dwells)
        print(f"graph-calib {args.command}: error: the input asks for more memory than this machine has "
              f"({_one_line(exc)}): shorten the record or program", file=sys.stderr)
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
