"""Simulated hand-held records whose gyro output stops at a range: calibrated kept whole and cut (docs/model.md).

Run from the repository root: ``.venv/bin/python scripts/saturation_monte_carlo.py SCENARIO RANGE_DPS SEEDS``
(``consumer-ferraris 175 10``: about a minute).  Each seed's record is simulated (``numpy.random.default_rng(seed)``,
seeds 0 to SEEDS-1), its gyro rates clipped at +-RANGE_DPS, and calibrated three ways with ``calibrate``'s defaults
(consumer grade, the factor graph): the clean record, the clipped record kept whole, and the clipped record cut after
each saturated episode (:func:`graph_calib.records.saturation.cut_at_range`).  Printed per way: the pooled RMS
and the largest of the normalised errors against the truth (every element with a sigma), and the verdicts passed.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from graph_calib.calibrate import calibrate  # noqa: E402
from graph_calib.model import ModelOptions  # noqa: E402
from graph_calib.options import CalibrationOptions  # noqa: E402
from graph_calib.records.saturation import cut_at_range  # noqa: E402
from graph_calib.simulation.scenarios import simulate  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenario")
    p.add_argument("range_dps", type=float)
    p.add_argument("seeds", type=int)
    args = p.parse_args(argv)
    R = np.radians(args.range_dps)
    options = CalibrationOptions(model=ModelOptions(grade="consumer"))
    z = {"clean": [], "kept whole": [], "cut": []}
    passed = dict.fromkeys(z, 0)
    episodes, cut = [], []
    for seed in range(args.seeds):
        made = simulate(args.scenario, rng=np.random.default_rng(seed)).plans[0].make()
        exp, truth = made.experiment, made.truth.values
        w = np.clip(exp.dtheta / exp.dt[:, None], -R, R)
        clipped = dataclasses.replace(exp, dtheta=w * exp.dt[:, None])
        cuts = cut_at_range(clipped, gyro_range_rps=R)
        episodes.append(cuts.episodes.shape[0])
        cut.append(int(cuts.cut.sum()))
        for name, record in (("clean", exp), ("kept whole", clipped), ("cut", cuts.experiment)):
            run = calibrate(record, options=options, solvers=("factor-graph",))
            r = run.results["factor-graph"]
            keys = [k for k in r.values if k in truth and r.sigmas[k] > 0]
            z[name].append([(r.values[k] - truth[k]) / r.sigmas[k] for k in keys])
            passed[name] += bool(run.verdict.passed)
    print(f"{args.scenario}, gyro range {args.range_dps:g} deg/s, seeds 0-{args.seeds - 1}: saturated episodes per "
          f"record {episodes}, cut {cut}")
    for name, v in z.items():
        a = np.array(v)
        print(f"  {name:10s} pooled RMS normalised error {np.sqrt(np.mean(a**2)):.2f}, largest {np.abs(a).max():.1f}, "
              f"verdicts passed {passed[name]}/{len(v)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
