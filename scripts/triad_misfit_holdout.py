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
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from graph_calib.calibrate import calibrate
from graph_calib.compensation.calibration import Calibration
from graph_calib.evaluation.crossval import cross_validate
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.simulation.scenarios import simulate

#: The rotation kind's variance factor of the gravity-only fit (its sigmas 100 times the gyro noise's).
GRAVITY_ONLY_FACTOR = 1e4


def fitter(options):
    return lambda train: Calibration.from_result(calibrate(train, options=options, solvers=("factor-graph",))
                                                 .results["factor-graph"])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--effect", default="gyro.g_sensitivity")
    p.add_argument("--effect-scale", type=float, default=1e4)
    p.add_argument("--poses", type=int, default=30)
    args = p.parse_args(argv)
    product = CalibrationOptions(model=ModelOptions(grade="consumer"))
    gravity_only = CalibrationOptions(model=ModelOptions(grade="consumer",
                                                         variance_factors={"rotation": GRAVITY_ONLY_FACTOR}))
    rows = []
    print(f"{'seed':>4} {'|f| spread [m/s^2]: raw':>24} {'gravity-only':>13} {'product':>10}   "
          f"{'transitions [deg]: raw':>22} {'gravity-only':>13} {'product':>10}   {'ratio':>6}")
    for seed in args.seeds:
        exp = simulate("consumer-handheld", rng=np.random.default_rng(seed), n_poses=args.poses,
                       effects=(args.effect,), effect_scale=args.effect_scale).plans[0].make().experiment
        g = cross_validate(exp, fit=fitter(gravity_only), folds=2, by="pairs")
        q = cross_validate(exp, fit=fitter(product), folds=2, by="pairs")
        raw, go, pr = g.pooled("raw"), g.pooled("calibrated"), q.pooled("calibrated")
        rows.append([raw["static_norm_std_mps2"], go["static_norm_std_mps2"], pr["static_norm_std_mps2"],
                     raw["transitions_rms_deg"], go["transitions_rms_deg"], pr["transitions_rms_deg"]])
        r = rows[-1]
        print(f"{seed:>4} {r[0]:>24.3e} {r[1]:>13.3e} {r[2]:>10.3e}   {r[3]:>22.3f} {r[4]:>13.3f} {r[5]:>10.3f}   "
              f"{r[2] / r[1]:>6.2f}", flush=True)
    r = np.sqrt(np.mean(np.square(rows), axis=0))
    print(f"{'all':>4} {r[0]:>24.3e} {r[1]:>13.3e} {r[2]:>10.3e}   {r[3]:>22.3f} {r[4]:>13.3f} {r[5]:>10.3f}   "
          f"{r[2] / r[1]:>6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
