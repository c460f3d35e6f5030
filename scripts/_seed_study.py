"""What the seed studies of ``scripts/`` share: the seed range argument, the case list, and the resumable loop
that writes one JSON file per (case, seed) (``noise_monte_carlo.py``, ``loop_false_adoption.py``)."""

from __future__ import annotations

from graph_calib.io import atomic_write_json


def seed_range(text):
    """``"A:B"`` -> ``range(A, B)`` (the ``--seeds`` argument)."""
    a, b = (int(x) for x in text.split(":"))
    return range(a, b)


def cases_of(parser, text, known):
    """The comma-separated cases of ``text``; ``parser.error`` naming any not in ``known``."""
    cases = text.split(",")
    unknown = [c for c in cases if c not in known]
    if unknown:
        parser.error(f"unknown cases {unknown}; known: {', '.join(known)}")
    return cases


def run_resumable(out, order, run, line):
    """``run(case, seed)`` for each ``(case, seed)`` of ``order`` whose ``OUT/CASE/seed-NNNN.json`` does not exist yet.

    Each record is written atomically (an interrupted study resumes where it stopped; NaN kept, as JSON's
    extension) and announced by ``print(line(case, seed, record))``.
    """
    for case in {c for c, _ in order}:
        (out / case).mkdir(parents=True, exist_ok=True)
    for case, seed in order:
        path = out / case / f"seed-{seed:04d}.json"
        if path.exists():
            continue
        record = run(case, seed)
        atomic_write_json(path, record, allow_nan=True)
        print(line(case, seed, record), flush=True)
