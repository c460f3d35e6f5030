"""One triad's misfit and the other's calibration, held out: the product against a gravity-only fit.

Each seed simulates ``consumer-handheld`` (30 poses) with an unmodelled gyro effect (``--effect``, default
``gyro.g_sensitivity``; ``--effect-scale``, default 1e4: about 0.1 deg/s/g; ``gyro.bias_dtdt`` is a bias drift while
the unit warms up) and cuts it into two folds by pairs (:mod:`graph_calib.evaluation.crossval`).  Each
fold is fitted twice: ``calibrate`` as it is (consumer grade, the factor graph), and a gravity-only accelerometer fit
(the same, the rotation kind's variance factor fixed at :data:`GRAVITY_ONLY_FACTOR`: the gyro integrals then hardly
weigh, the attitudes of the rests come from gravity alone).  Prints the held-out |f| spread (m/s^2) and transitions
(deg) of raw, the gravity-only fit and the product per seed and pooled, and the product's |f| spread over the
gravity-only fit's.  ``calibrate`` stages its solve when the gyro model does not fit
(:mod:`graph_calib.solvers.staged`); the gravity-only fit fixes the rotation kind's factor, which the staging leaves
alone.

    PYTHONPATH=$PWD python scripts/triad_misfit_holdout.py --seeds 1 2 3
    PYTHONPATH=$PWD python scripts/triad_misfit_holdout.py --seeds 1 2 3 --effect gyro.bias_dtdt --effect-scale 3e4
    PYTHONPATH=$PWD python scripts/triad_misfit_holdout.py --seeds 1 2 3 --diagnose

``--truth`` adds the true calibration's held-out figures (what the record's noise allows). ``--diagnose`` adds a third fit, ``diagnose`` (the loop as it runs by default, the factor graph), and prints its
held-out figures and ratio too; ``--holdout`` runs that loop with its held-out guard (``DiagnosisOptions.holdout``,
off by default: :mod:`graph_calib.diagnosis.holdout`).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from graph_calib.calibrate import calibrate, calibrate_with_effects
from graph_calib.compensation.calibration import Calibration
from graph_calib.diagnosis import DiagnosisOptions, diagnose
from graph_calib.evaluation.crossval import cross_validate
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.simulation.scenarios import simulate

#: The rotation kind's variance factor of the gravity-only fit (its sigmas 100 times the gyro noise's).
GRAVITY_ONLY_FACTOR = 1e4


def fitter(options):
    return lambda train: Calibration.from_result(calibrate(train, options=options, solvers=("factor-graph",))
                                                 .results["factor-graph"])


def diagnose_fitter(options, *, holdout=False):
    def fit(train):
        diag = diagnose(train, options=options, diagnosis=DiagnosisOptions(solvers=("factor-graph",), holdout=holdout))
        print(f"  loop added: {', '.join(diag.added) or 'nothing'}", flush=True)
        # what graph-calib diagnose writes: the final model solved as calibrate solves it (variance components)
        return Calibration.from_result(calibrate_with_effects(train, added=diag.added, options=options,
                                                              solvers=("factor-graph",)).results["factor-graph"])
    return fit


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--effect", default="gyro.g_sensitivity")
    p.add_argument("--effect-scale", type=float, default=1e4)
    p.add_argument("--poses", type=int, default=30)
    p.add_argument("--diagnose", action="store_true", help="also fit with diagnose (the loop)")
    p.add_argument("--holdout", action="store_true", help="the loop of --diagnose with its held-out guard")
    p.add_argument("--still-rests", action="store_true", help="the product's rests still (ModelOptions.still_at_rest)")
    p.add_argument("--truth", action="store_true",
                   help="also print the true calibration's held-out figures (the floor the record's noise sets)")
    args = p.parse_args(argv)
    product = CalibrationOptions(model=ModelOptions(grade="consumer", still_at_rest=args.still_rests))
    gravity_only = CalibrationOptions(model=ModelOptions(grade="consumer",
                                                         variance_factors={"rotation": GRAVITY_ONLY_FACTOR}))
    rows = []
    head = (f"{'seed':>4} {'|f| spread [m/s^2]: raw':>24} {'gravity-only':>13} {'product':>10}"
            + (f" {'diagnose':>10}" if args.diagnose else "") + (f" {'truth':>10}" if args.truth else "")
            + f"   {'transitions [deg]: raw':>22} {'gravity-only':>13} {'product':>10}"
            + (f" {'diagnose':>10}" if args.diagnose else "") + (f" {'truth':>10}" if args.truth else "")
            + f"   {'ratio':>6}" + (f" {'diag':>6}" if args.diagnose else "") + (f" {'truth':>6}" if args.truth else ""))
    print(head)

    def line(label, r):
        k = 3 + args.diagnose + args.truth
        f, t = r[:k], r[k:]
        text = f"{label:>4} {f[0]:>24.3e} " + " ".join(f"{v:>{13 if i == 0 else 10}.3e}" for i, v in enumerate(f[1:]))
        text += f"   {t[0]:>22.3f} " + " ".join(f"{v:>{13 if i == 0 else 10}.3f}" for i, v in enumerate(t[1:]))
        text += "   " + " ".join(f"{v / f[1]:>6.2f}" for v in f[2:])
        print(text, flush=True)

    for seed in args.seeds:
        made = simulate("consumer-handheld", rng=np.random.default_rng(seed), n_poses=args.poses,
                        effects=(args.effect,), effect_scale=args.effect_scale).plans[0].make()
        exp, truth = made.experiment, Calibration.from_result(made.truth)
        cvs = [cross_validate(exp, fit=fitter(gravity_only), folds=2, by="pairs"),
               cross_validate(exp, fit=fitter(product), folds=2, by="pairs")]
        if args.diagnose:
            cvs.append(cross_validate(exp, fit=diagnose_fitter(product, holdout=args.holdout), folds=2, by="pairs"))
        if args.truth:
            cvs.append(cross_validate(exp, fit=lambda train: truth, folds=2, by="pairs"))
        raw = cvs[0].pooled("raw")
        fits = [cv.pooled("calibrated") for cv in cvs]
        rows.append([raw["static_norm_std_mps2"]] + [f["static_norm_std_mps2"] for f in fits]
                    + [raw["transitions_rms_deg"]] + [f["transitions_rms_deg"] for f in fits])
        line(str(seed), rows[-1])
    line("all", np.sqrt(np.mean(np.square(rows), axis=0)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
