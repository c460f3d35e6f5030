"""Monte Carlo check of ``graph-calib predict``: (estimate - truth) / predicted sigma over many seeds.

``PYTHONPATH=. python scripts/predict_monte_carlo.py [--seeds 20] [--hours 0.25] [--solver factor-graph]
[--elements] [--save z.npz]``

Each seed simulates the shortened navigation-grade programme (``nav-subrange-short``, noise on, linear
temperature truth), predicts its accuracy (:func:`graph_calib.design.prediction.predict`) and calibrates it;
prints the RMS of z = (estimate - truth) / predicted sigma per parameter (its elements pooled) and the
range of the per-element RMS, with the chi-square band of that many seeds.  docs/design.md records the
figures (tests/design/test_prediction.py runs the same 20 seeds).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import chi2

from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.design.prediction import predict
from graph_calib.simulation import simulate


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--first-seed", type=int, default=2000)
    p.add_argument("--hours", type=float, default=0.25)
    p.add_argument("--solver", default="factor-graph")
    p.add_argument("--elements", action="store_true", help="print every element's RMS(z) too")
    p.add_argument("--save", help="write the z table (seeds x elements) and the names to this .npz")
    args = p.parse_args(argv)
    z, t_pred, t_solve = [], 0.0, 0.0
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        se = simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=args.hours,
                      curvature=False).run()[0]
        opts = CalibrationOptions(t_ref_degC=se.truth.t_ref_degC)
        problem = build_problem(se.experiment, options=opts)
        t0 = time.perf_counter()
        pred = predict(problem)
        t1 = time.perf_counter()
        res = solve_problem(problem, options=opts, solvers=(args.solver,)).results[args.solver]
        t2 = time.perf_counter()
        t_pred += t1 - t0
        t_solve += t2 - t1
        s = pred.sigmas()
        z.append([(res.values[n] - se.truth.values[n]) / s[n] for n in pred.names])
    z = np.array(z)
    names = pred.names
    n = args.seeds
    print(f"{n} seeds of nav-subrange-short, {args.hours} h, {args.solver}; predict {t_pred / n:.2f} s, "
          f"solve {t_solve / n:.2f} s per seed")
    print("parameter                 elements  RMS(z)")
    for g in res.effects:
        cols = [i for i, nm in enumerate(names) if nm.startswith(g + ".")]
        print(f"  {g:<24}{len(cols):>6}  {np.sqrt(np.mean(z[:, cols] ** 2)):.3f}")
    rms = np.sqrt(np.mean(z**2, axis=0))
    if args.elements:
        for nm, v in zip(names, rms):
            print(f"    {nm:<28}{v:.3f}")
    if args.save:
        np.savez(args.save, z=z, names=np.array(names))
    lo, hi = np.sqrt(chi2.ppf([0.0005, 0.9995], n) / n)
    i, j = int(np.argmin(rms)), int(np.argmax(rms))
    print(f"per element RMS(z): {rms.min():.3f} ({names[i]}) .. {rms.max():.3f} ({names[j]}); "
          f"{np.mean((rms >= 0.8) & (rms <= 1.25)):.0%} of {rms.size} within [0.8, 1.25]; "
          f"99.9 % chi-square band of {n} seeds [{lo:.3f}, {hi:.3f}]")
    print(f"all elements pooled: RMS(z) {np.sqrt(np.mean(z**2)):.3f}; |z| < 3: {np.mean(np.abs(z) < 3):.1%}")


if __name__ == "__main__":
    main()
