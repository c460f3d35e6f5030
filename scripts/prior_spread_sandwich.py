"""How much of a reported sigma is the prior's, and what it becomes when the truth is narrower than the prior.

``PYTHONPATH=. python scripts/prior_spread_sandwich.py [--seeds 50000] [--hours 0.1] [--priors grade|truth]``

For a seed of ``nav-subrange-short`` (the noise Monte Carlo's records, ``scripts/noise_monte_carlo.py``), the
whole linearised system of the factor graph at the nominal calibration (every factor whitened as the model
whitens it on the identified noise, the priors) gives the model's covariance ``C = [H^-1]_xx`` of the
calibration. To first order the estimate's error is ``C (data term) + C P^-1 (mu - x_true)``; when the data
noise is as modelled and the truth is drawn with second moments ``S_t`` (diagonal), its covariance is

    C_true = C + C P^-1 (S_t - P) P^-1 C.

The simulator draws each element as ``sign * U(low, high)`` of the grade's range
(``graph_calib.simulation.truth.TRUTH_RANGES``), RMS ``sqrt((high^3 - low^3) / (3 (high - low)))``: 2 to 38
times narrower than the navigation grade's prior sigmas. Printed per element that is not prior-dominated:
``sqrt(C_true / C)``, the RMS normalised error a Monte Carlo over the simulator's IMUs must find when the noise
model is right (1 when the truth is drawn from the prior; ``--priors truth`` sets the priors to the truth's
RMS, where it is 1 by construction). No noise is drawn: no Monte Carlo scatter.
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.sparse.linalg as spla

from encoder_noise_sandwich import _system
from graph_calib.calibrate import build_problem
from graph_calib.model import ModelOptions
from graph_calib.navigation.rotations import quat_to_dcm
from graph_calib.options import CalibrationOptions
from graph_calib.simulation import simulate
from noise_monte_carlo import truth_spread_priors


def prior_spread_ratio(se, *, priors="grade"):
    """``(names, sqrt(C_true / C) (P,), sigma / prior sigma (P,))`` of one simulated experiment."""
    model_options = ModelOptions(prior_sigma=truth_spread_priors()) if priors == "truth" else ModelOptions()
    problem = build_problem(se.experiment, options=CalibrationOptions(model=model_options,
                                                                      t_ref_degC=se.truth.t_ref_degC))
    model = problem.model
    x0 = model.layout.zeros()
    R = model.propagate(quat_to_dcm(problem.q_nb0), model.preintegrate(x0), x0)
    J, _, na, P = _system(model, R, x0, problem.q_nb0)
    E = np.zeros((na + P, P))
    E[na:] = np.eye(P)
    C = spla.splu((J.T @ J).tocsc()).solve(E)[na:]
    names = model.layout.element_names()
    _, prior = model.prior()
    spread = truth_spread_priors()
    s_t = np.array([spread[n.rsplit(".", 1)[0] if n.rsplit(".", 1)[0] in spread else n] for n in names])
    C_true = C + C @ np.diag((s_t**2 - prior**2) / prior**4) @ C
    return names, np.sqrt(np.diag(C_true) / np.diag(C)), np.sqrt(np.diag(C)) / prior


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[50000])
    p.add_argument("--hours", type=float, default=0.1)
    p.add_argument("--priors", choices=("grade", "truth"), default="grade")
    args = p.parse_args(argv)
    for seed in args.seeds:
        se = simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=args.hours).run()[0]
        names, ratio, dom = prior_spread_ratio(se, priors=args.priors)
        print(f"seed {seed}, priors {args.priors}: sqrt(C_true / C) of the elements the data determine "
              f"(sigma / prior sigma <= 0.7)")
        print("  " + ", ".join(f"{n} {r:.2f}" for n, r, d in zip(names, ratio, dom) if d <= 0.7))
        print("  prior-dominated: " + ", ".join(f"{n} {d:.2f}" for n, d in zip(names, dom) if d > 0.7))


if __name__ == "__main__":
    main()
