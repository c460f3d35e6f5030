"""``calibrate --effect gyro.g_sensitivity`` on a simulated consumer record, from scratch and warm-started.

Issue #13 (the gyros' g-sensitivity sees the calibrated specific force): a ``consumer-ferraris`` session
with ``gyro.g_sensitivity`` switched on at a MEMS size (``--effect-scale``, default 1e4: about
0.1 deg/s/g), calibrated with the effect by both solvers from the prior and warm-started from the declared
model's factor-graph solution (as the closed loop does when it adds the effect).  Prints, for the nine
``G`` elements, the error against the truth in sigma, filter minus graph in sigma, and warm minus scratch
in sigma.  Takes a few minutes (too long for the test suite); figures in docs/model.md.

Usage::

    PYTHONPATH=. .venv/bin/python scripts/triad_coupling_check.py [--seed 3] [--effect-scale 1e4]
"""

from __future__ import annotations

import argparse

import numpy as np

from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
from graph_calib.model import ModelOptions
from graph_calib.simulation import simulate
from graph_calib.solvers.registry import solve

EFFECT = "gyro.g_sensitivity"
SOLVERS = ("sqrt-kf", "factor-graph")


def _options(se, effects):
    return CalibrationOptions(model=ModelOptions(grade="consumer", extra_effects=effects),
                              t_ref_degC=se.truth.t_ref_degC)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--effect-scale", type=float, default=1e4)
    a = ap.parse_args()
    se = simulate("consumer-ferraris", rng=np.random.default_rng(a.seed), effects=(EFFECT,),
                  effect_scale=a.effect_scale).run()[0]
    opts = _options(se, (EFFECT,))
    problem = build_problem(se.experiment, options=opts)
    scratch = dict(solve_problem(problem, options=opts, solvers=SOLVERS).outputs)
    opts0 = _options(se, ())
    problem0 = build_problem(se.experiment, options=opts0)
    out0 = solve("factor-graph", problem0, options=opts0)
    x0 = problem.model.layout.embed(problem0.model.layout, out0.x)
    warm = {name: solve(name, problem, options=opts, initial=(out0.attitudes, x0)) for name in SOLVERS}
    layout = problem.model.layout
    names = layout.element_names()
    truth = np.array([se.truth.values[n] for n in names])
    g = np.arange(layout.size)[layout.slice(EFFECT)]
    sig = {k: np.sqrt(np.diag(o.covariance)) for k, o in scratch.items()}
    print("truth G, rad/s per m/s^2: " + " ".join(f"{v:+.2e}" for v in truth[g]))
    print("sigma G (factor graph):   " + " ".join(f"{v:.2e}" for v in sig["factor-graph"][g]))
    np.set_printoptions(precision=3, suppress=True, linewidth=140)
    for k in SOLVERS:
        o, w = scratch[k], warm[k]
        z = (o.x - truth) / sig[k]
        print(f"{k}: scratch {o.iterations} iterations (converged {o.converged}), warm {w.iterations} "
              f"(converged {w.converged})")
        print(f"  G error / sigma:          {z[g]}   (max |z| over all elements {np.abs(z).max():.2f}, "
              f"{names[int(np.argmax(np.abs(z)))]})")
        d = (w.x - o.x) / sig[k]
        print(f"  warm - scratch, sigma:    max {np.abs(d).max():.4f} ({names[int(np.argmax(np.abs(d)))]})")
    d = (scratch["sqrt-kf"].x - scratch["factor-graph"].x) / sig["factor-graph"]
    print(f"filter - graph, G / sigma: {d[g]}  (max over all {np.abs(d).max():.3f})")


if __name__ == "__main__":
    main()
