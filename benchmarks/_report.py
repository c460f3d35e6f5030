"""The headline figures of a benchmark, in one line each that ``benchmarks/run_all.py`` collects.

A benchmark prints its usual human output and, for each headline figure, one line::

    BENCH {"key": "solve_s", "what": "factor graph solve", "value": 4.21, "unit": "s"}

``report`` prints it (flushed, so the line follows the human output it summarises).
"""

import json
import math

PREFIX = "BENCH "


def report(key, value, unit, what):
    """Print one headline figure: ``key`` (short, unique in the benchmark), ``value``, ``unit``, ``what``."""
    value = float(value)
    print(PREFIX + json.dumps({"key": key, "what": what, "value": value if math.isfinite(value) else None,
                               "unit": unit}), flush=True)


def parse(line):
    """The figure of a ``BENCH`` line as a dict, or None for any other line."""
    if not line.startswith(PREFIX):
        return None
    try:
        fig = json.loads(line[len(PREFIX):])
    except ValueError:
        return None
    return fig if isinstance(fig, dict) and "key" in fig else None
