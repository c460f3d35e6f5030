"""The product against imucal's Ferraris calibration, out of sample, on hand-held Ferraris sessions (issue 22).

Each seed simulates ``consumer-ferraris`` as a hand makes it (:data:`graph_calib.simulation.scenarios.SHORT_REST_FERRARIS`:
rests of 0.5-1.5 s, a swaying hand, the record starting in motion), cuts it into two folds
(:func:`graph_calib.evaluation.crossval.make_folds`, by pairs), calibrates without each fold (``calibrate``, the
factor graph, the consumer grade, the moving keyframes' gravity sigma and the hand's sway at rest estimated: the
README's options for a swaying hand) and judges on it; imucal's closed-form Ferraris calibration (fitted on the whole
record's six faces and three turns, as a lab would) is judged on the same held-out parts, and so is the simulator's
true calibration (the floor of any calibration fitted without those parts: imucal, fitted on them too, may go below
it).  Prints per seed and pooled the held-out transition rms and |f| spread of raw, truth, imucal and the product
(``--diagnose``: the loop's calibration).

    PYTHONPATH=$PWD python scripts/handheld_vs_imucal.py --seeds 1 2 3 [--diagnose] [--guess] [--sway-sigma none]
        [--still-rests] [--by faces] [--triads]

``--triads`` adds the calibrations made of one calibration's gyro and another's accelerometer (``gyro/accel``: truth,
imucal, product), which tells which triad a held-out gap sits in.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "peers"))

from imucal_peer import imucal_ferraris  # noqa: E402

from graph_calib.calibrate import calibrate  # noqa: E402
from graph_calib.compensation.calibration import Calibration  # noqa: E402
from graph_calib.errors import InputError  # noqa: E402
from graph_calib.evaluation.crossval import (face_to_face_folds, held_out_figures, make_folds, record_rests,
                                             training_record)  # noqa: E402
from graph_calib.model import ModelOptions  # noqa: E402
from graph_calib.options import CalibrationOptions  # noqa: E402
from graph_calib.simulation.scenarios import SHORT_REST_FERRARIS, simulate  # noqa: E402

#: The product's options for a swaying hand (README): consumer grade, the moving keyframes' gravity sigma and the hand's
#: sway at rest estimated (``--moving-sigma estimate --sway-sigma estimate``).
CONSUMER = CalibrationOptions(model=ModelOptions(grade="consumer", moving_sigma="estimate", sway_sigma="estimate"))


def product_options(*, guess=False, sway="estimate", still=False):
    """The product's options: :data:`CONSUMER`, the moving sigma left at its guess (``guess``), ``sway`` (a sigma in
    m/s^2, ``"estimate"`` or None: no sway term), the rests still (``still``: ``--still-rests``)."""
    model = ModelOptions(grade="consumer", moving_sigma=None if guess else "estimate", sway_sigma=sway,
                         still_at_rest=still)
    return CalibrationOptions(model=model)


def sway_option(text):
    """``--sway-sigma``'s value: ``estimate``, ``none`` or a number of m/s^2."""
    return text if text == "estimate" else None if text == "none" else float(text)
#: The calibrations judged, in the order of the table's columns.
NAMES = ("raw", "truth", "imucal", "product")
#: ``--triads``: (gyro from, accelerometer from) of the mixed calibrations judged besides.
TRIAD_MIXES = (("truth", "product"), ("product", "truth"), ("imucal", "truth"), ("truth", "imucal"),
               ("imucal", "product"), ("product", "imucal"))


class TriadMix:
    """The gyro of one calibration and the accelerometer of another, behind the ``correct`` interface."""

    def __init__(self, gyro, accel):
        self.gyro, self.accel = gyro, accel

    def correct(self, experiment):
        return self.gyro.correct(experiment)[0], self.accel.correct(experiment)[1]


def session(seed):
    """The simulated short-rest Ferraris session of ``seed``: ``(Experiment, its true Calibration)``."""
    sim = simulate("consumer-ferraris", rng=np.random.default_rng(seed), tag=f"seed {seed}", **SHORT_REST_FERRARIS)
    made = sim.plans[0].make()
    return made.experiment, Calibration.from_result(made.truth)


def product_fit(train, *, options=CONSUMER):
    """``calibrate``'s factor-graph result on a training record, as a Calibration."""
    return Calibration.from_result(calibrate(train, options=options, solvers=("factor-graph",)).results["factor-graph"])


def diagnose_fit(train, *, options=CONSUMER):
    """``diagnose``'s factor-graph result on a training record, as a Calibration: the final model solved as
    ``graph-calib diagnose`` writes it (as ``calibrate`` solves it, variance components included)."""
    from graph_calib.calibrate import calibrate_with_effects
    from graph_calib.diagnosis import DiagnosisOptions, diagnose
    diag = diagnose(train, options=options, diagnosis=DiagnosisOptions(solvers=("factor-graph",)))
    print(f"  loop added: {', '.join(diag.added) or 'nothing'}", flush=True)
    return Calibration.from_result(calibrate_with_effects(train, added=diag.added, options=options,
                                                          solvers=("factor-graph",)).results["factor-graph"])


def compare(seed, *, folds=2, by="pairs", fit=product_fit, triads=False):
    """``{name: [(transitions rms deg, |f| spread m/s^2) per fold]}`` for raw, truth, imucal and the product (and,
    ``triads``, the :data:`TRIAD_MIXES` named ``gyro/accel``)."""
    exp, truth = session(seed)
    rests = record_rests(exp)
    peer = imucal_ferraris(exp, rests)
    names = NAMES + (tuple(f"{g}/{a}" for g, a in TRIAD_MIXES) if triads else ())
    out = {name: [] for name in names}
    made = (face_to_face_folds(exp, folds=folds, rests=rests) if by == "faces"
            else make_folds(exp, folds=folds, by=by, rests=rests))
    for fold in made:
        try:
            cal = fit(training_record(exp, fold, rests=rests))
        except InputError as e:
            print(f"  seed {seed} fold {fold.index + 1}: not calibrated: {e}", flush=True)
            for name in names:
                out[name].append((np.nan, np.nan))
            continue
        cals = dict(zip(NAMES, (None, truth, peer, cal)))
        if triads:
            cals.update({f"{g}/{a}": TriadMix(cals[g], cals[a]) for g, a in TRIAD_MIXES})
        for name, c in cals.items():
            f = held_out_figures(exp, fold, c)
            out[name].append((f.transitions_rms_deg, f.static_norm_std_mps2))
    return out


def pooled(rows):
    """RMS over the rows of each column."""
    a = np.asarray(rows, dtype=float)
    with warnings.catch_warnings():     # --by faces holds out no rest: the |f| column is all NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.sqrt(np.nanmean(a ** 2, axis=0))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 11)))
    p.add_argument("--by", choices=("pairs", "rests", "transitions", "faces"), default="pairs",
                   help="folds (graph_calib.evaluation.crossval), or faces: the face-to-face motions only")
    p.add_argument("--diagnose", action="store_true", help="fit with diagnose (the loop) instead of calibrate")
    p.add_argument("--guess", action="store_true", help="the moving keyframes' gravity sigma left at its 1 m/s^2 guess")
    p.add_argument("--sway-sigma", type=sway_option, default="estimate",
                   help="the product's sway sigma: 'estimate' (default), 'none' or m/s^2")
    p.add_argument("--still-rests", action="store_true", help="the product's rests still (ModelOptions.still_at_rest)")
    p.add_argument("--triads", action="store_true",
                   help="also judge one calibration's gyro with another's accelerometer (pooled transitions)")
    args = p.parse_args(argv)
    every = {name: [] for name in NAMES}
    print(f"{'seed':>4} {'fold':>4} {'transitions rms [deg]':>44} {'|f| spread [m/s^2]':>52}")
    print(f"{'':>4} {'':>4} " + " ".join(f"{n:>10}" for n in NAMES) + " " + " ".join(f"{n:>12}" for n in NAMES))
    for seed in args.seeds:
        options = product_options(guess=args.guess, sway=args.sway_sigma, still=args.still_rests)
        fit = diagnose_fit if args.diagnose else product_fit
        res = compare(seed, by=args.by, fit=lambda train: fit(train, options=options), triads=args.triads)
        for j in range(len(res["raw"])):
            print(f"{seed:>4} {j + 1:>4} " + " ".join(f"{res[n][j][0]:>10.3f}" for n in NAMES) + " "
                  + " ".join(f"{res[n][j][1]:>12.3e}" for n in NAMES), flush=True)
        for k in res:
            every.setdefault(k, []).extend(res[k])
    p = {n: pooled(every[n]) for n in NAMES}
    print(f"{'all':>4} {'':>4} " + " ".join(f"{p[n][0]:>10.3f}" for n in NAMES) + " "
          + " ".join(f"{p[n][1]:>12.3e}" for n in NAMES))
    if args.triads:
        print("pooled transitions rms [deg], gyro/accel: " + ", ".join(
            f"{name} {pooled(rows)[0]:.4f}" for name, rows in every.items() if "/" in name))
    return 0


if __name__ == "__main__":
    sys.exit(main())
