"""The product against imucal's Ferraris calibration, out of sample, on hand-held Ferraris sessions (issue 22).

Each seed simulates ``consumer-ferraris`` as a hand makes it (:data:`graph_calib.simulation.scenarios.SHORT_REST_FERRARIS`:
rests of 0.5-1.5 s, a swaying hand, the record starting in motion), cuts it into two folds
(:func:`graph_calib.evaluation.crossval.make_folds`, by pairs), calibrates without each fold (``calibrate``, the
factor graph, the consumer grade) and judges on it; imucal's closed-form Ferraris calibration (fitted on the whole
record's six faces and three turns, as a lab would) is judged on the same held-out parts.  Prints per seed and pooled
the held-out transition rms and |f| spread of raw, imucal and the product (``--diagnose``: the loop's calibration).

    PYTHONPATH=$PWD python scripts/handheld_vs_imucal.py --seeds 1 2 3 [--diagnose] [--guess]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "peers"))

from imucal_peer import imucal_ferraris  # noqa: E402

from graph_calib.calibrate import calibrate  # noqa: E402
from graph_calib.compensation.calibration import Calibration  # noqa: E402
from graph_calib.evaluation.crossval import held_out_figures, make_folds, record_rests, training_record  # noqa: E402
from graph_calib.model import ModelOptions  # noqa: E402
from graph_calib.options import CalibrationOptions  # noqa: E402
from graph_calib.simulation.scenarios import SHORT_REST_FERRARIS, simulate  # noqa: E402

#: The product's options: consumer grade, the moving keyframes' gravity sigma estimated (``--moving-sigma estimate``).
CONSUMER = CalibrationOptions(model=ModelOptions(grade="consumer", moving_sigma="estimate"))


def session(seed):
    """The simulated short-rest Ferraris session of ``seed`` (an Experiment)."""
    sim = simulate("consumer-ferraris", rng=np.random.default_rng(seed), tag=f"seed {seed}", **SHORT_REST_FERRARIS)
    return sim.plans[0].make().experiment


def product_fit(train, *, options=CONSUMER):
    """``calibrate``'s factor-graph result on a training record, as a Calibration."""
    return Calibration.from_result(calibrate(train, options=options, solvers=("factor-graph",)).results["factor-graph"])


def diagnose_fit(train, *, options=CONSUMER):
    """``diagnose``'s factor-graph result (the loop, its held-out guard on) on a training record, as a Calibration."""
    from graph_calib.diagnosis import DiagnosisOptions, diagnose
    diag = diagnose(train, options=options, diagnosis=DiagnosisOptions(solvers=("factor-graph",)))
    print(f"  loop added: {', '.join(diag.added) or 'nothing'}", flush=True)
    return Calibration.from_result(diag.after.results["factor-graph"])


def compare(seed, *, folds=2, by="pairs", fit=product_fit):
    """``{name: [(transitions rms deg, |f| spread m/s^2) per fold]}`` for raw, imucal and the product."""
    exp = session(seed)
    rests = record_rests(exp)
    peer = imucal_ferraris(exp, rests)
    out = {"raw": [], "imucal": [], "product": []}
    for fold in make_folds(exp, folds=folds, by=by, rests=rests):
        cal = fit(training_record(exp, fold, rests=rests))
        for name, c in (("raw", None), ("imucal", peer), ("product", cal)):
            f = held_out_figures(exp, fold, c)
            out[name].append((f.transitions_rms_deg, f.static_norm_std_mps2))
    return out


def pooled(rows):
    """RMS over the rows of each column."""
    a = np.asarray(rows, dtype=float)
    return np.sqrt(np.nanmean(a ** 2, axis=0))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 11)))
    p.add_argument("--by", choices=("pairs", "rests", "transitions"), default="pairs")
    p.add_argument("--diagnose", action="store_true", help="fit with diagnose (the loop) instead of calibrate")
    p.add_argument("--guess", action="store_true", help="the moving keyframes' gravity sigma left at its 1 m/s^2 guess")
    args = p.parse_args(argv)
    every = {"raw": [], "imucal": [], "product": []}
    print(f"{'seed':>4} {'fold':>4} {'transitions rms [deg]':>32} {'|f| spread [m/s^2]':>36}")
    print(f"{'':>4} {'':>4} {'raw':>10} {'imucal':>10} {'product':>10} {'raw':>12} {'imucal':>12} {'product':>12}")
    for seed in args.seeds:
        options = CalibrationOptions(model=ModelOptions(grade="consumer")) if args.guess else CONSUMER
        fit = diagnose_fit if args.diagnose else product_fit
        res = compare(seed, by=args.by, fit=lambda train: fit(train, options=options))
        for j in range(len(res["raw"])):
            r, i, q = res["raw"][j], res["imucal"][j], res["product"][j]
            print(f"{seed:>4} {j + 1:>4} {r[0]:>10.3f} {i[0]:>10.3f} {q[0]:>10.3f} {r[1]:>12.3e} {i[1]:>12.3e} {q[1]:>12.3e}",
                  flush=True)
        for k in every:
            every[k].extend(res[k])
    r, i, q = (pooled(every[k]) for k in ("raw", "imucal", "product"))
    print(f"{'all':>4} {'':>4} {r[0]:>10.3f} {i[0]:>10.3f} {q[0]:>10.3f} {r[1]:>12.3e} {i[1]:>12.3e} {q[1]:>12.3e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
