"""Monte Carlo of the noise cases of issue #21: identified noise, sigmas and residual statistics on simulated records.

Each case is a noise option of the simulator's table scenarios (``graph_calib.simulation.scenarios``:
``noise_factor``, ``encoder_noise_arcsec``, ``gyro_quantization_arcsec``, ``start_in_motion``); each run simulates
``nav-subrange-short`` for ``--hours`` with one seed, calibrates it as ``graph-calib calibrate`` does (noise
identified from the record, variance components, structure tests, both default solvers) and writes one JSON file
``OUT/CASE/seed-NNNN.json``: the identified densities over the simulated ones, each solver's normalised errors
``(estimate - truth) / sigma`` per element, the prior-dominated elements, each kind's chi2 / redundancy and
variance factor, the verdict. A file that exists is not run again (the study resumes after an interruption).
``--summary`` reads the files and prints, per case: the density ratios, the pooled RMS of the normalised errors
over the elements the data determine (both solvers), the per-element RMS against the chi-square limits of the
number of seeds, the kinds' chi2 / redundancy range and the verdicts.

The normalised error is chi-square only when the truth is drawn from the priors; the simulator draws it
narrower (``simulation/truth.py``), so elements tied to directions a short record does not determine look
pessimistic whatever the noise model (docs/model.md, "Noise from the record"). ``--priors truth`` calibrates
with the truth draw's RMS as the priors (:func:`truth_spread_priors`), which judges the noise model alone; each
file also holds ``z_data`` (:func:`data_part_z`), the error with the prior's pull removed over the data's part
of the sigma. Use a new ``--out`` for each code version or prior choice (a file records ``priors``).

Usage::

    python scripts/noise_monte_carlo.py --out /tmp/noise-mc --cases clean,noise-0.3x --seeds 0:20
    python scripts/noise_monte_carlo.py --out /tmp/noise-mc-truth --priors truth --cases clean --seeds 0:40
    python scripts/noise_monte_carlo.py --out /tmp/noise-mc --summary
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

from graph_calib.calibrate import build_problem, solve_problem
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.simulation import simulate
from graph_calib.simulation.truth import draw_rms
from graph_calib.solvers.registry import DEFAULT_SOLVERS

from _seed_study import cases_of, run_resumable, seed_range  # scripts/: run as a script, its folder on sys.path

#: The cases: name -> the simulator's noise options.
CASES = {
    "clean": {},
    "noise-0.3x": {"noise_factor": 0.3},
    "noise-3x": {"noise_factor": 3.0},
    "start-in-motion": {"start_in_motion": True},
    "table-0": {"encoder_noise_arcsec": 0.0},
    "table-0.5": {"encoder_noise_arcsec": 0.5},
    "table-2": {"encoder_noise_arcsec": 2.0},
    "table-5": {"encoder_noise_arcsec": 5.0},
    "quantization-0.5": {"gyro_quantization_arcsec": 0.5},
}

SEED_BASE = 50_000


def truth_spread_priors(grade="navigation"):
    """``{parameter: sigma}``: the RMS of the simulator's draw of each declared parameter
    (:func:`graph_calib.simulation.truth.draw_rms`), the priors of ``--priors truth``."""
    return draw_rms(grade)


def run_one(case, seed, *, hours, priors="grade"):
    """One simulated record of ``case`` calibrated as ``calibrate`` does; a JSON-ready dict.

    ``priors``: ``"grade"`` (the product's, as ``calibrate``) or ``"truth"`` (:func:`truth_spread_priors`).
    """
    t0 = time.perf_counter()
    se = simulate("nav-subrange-short", rng=np.random.default_rng(SEED_BASE + seed), hours=hours,
                  **CASES[case]).run()[0]
    model_options = ModelOptions(prior_sigma=truth_spread_priors()) if priors == "truth" else ModelOptions()
    options = CalibrationOptions(model=model_options, t_ref_degC=se.truth.t_ref_degC)
    problem = build_problem(se.experiment, options=options)
    run = solve_problem(problem, options=options, solvers=DEFAULT_SOLVERS)
    sim_noise = se.truth.extra["simulation"]["noise"]
    out = {"case": case, "seed": seed, "hours": hours, "priors": priors, "simulated_noise": sim_noise,
           "verdict": {"passed": bool(run.verdict.passed), "problems": list(run.verdict.problems),
                       "notes": list(run.verdict.notes)},
           "solvers": {}}
    for name, res in run.results.items():
        identified = res.extra.get("noise", {}).get("identified") or {}
        names = list(res.values)
        z = [(res.values[n] - se.truth.values[n]) / res.sigmas[n] for n in names]
        z_data = data_part_z(problem.model, res, se.truth.values, names)
        out["solvers"][name] = {
            "names": names, "z": z, "z_data": z_data, "prior_dominated": list(res.extra.get("prior_dominated", {})),
            "kinds": {k: {"chi2_per_redundancy": v.get("chi2_per_redundancy"),
                          "variance_factor": v.get("variance_factor")}
                      for k, v in res.residuals.get("kinds", {}).items()},
            "noise": {s: {"density": (identified.get(s) or {}).get("density")} for s in ("gyro", "accel")},
            "encoder": identified.get("encoder"),
            "noise_used": {k: v for k, v in res.extra.get("noise", {}).items() if k != "identified"},
        }
    out["seconds"] = time.perf_counter() - t0
    return out


def data_part_z(model, res, truth, names):
    """Each element's error with the prior's pull on it removed, over the data's part of its sigma.

    To first order a solver's error is ``C (data term) + C P^-1 (mu - x_true)`` (``C`` its covariance, ``P``
    the prior covariance, ``mu`` the prior mean): the data term has covariance ``C - C P^-1 C`` when the noise
    model is right, and the prior's pull is known once the truth is.  The plain ``(estimate - truth) / sigma``
    is chi-square only when the truth is drawn from the prior; the simulator draws each element as
    ``sign * U(low, high)`` of the grade's range (``simulation/truth.py``), 2 to 38 times narrower than the
    grade's prior sigma, so an element correlated with a direction the record does not determine (its
    sigma largely the prior's) shows errors smaller than its sigma whatever the noise model.  This figure
    judges the noise model alone.  None where the result has no covariance.
    """
    if res.covariance is None:
        return None
    order = [list(res.covariance_names).index(n) for n in names]
    C = np.asarray(res.covariance, dtype=float)[np.ix_(order, order)]
    mu, prior_sigma = model.prior()
    idx = [model.layout.element_names().index(n) for n in names]
    p_inv = 1.0 / prior_sigma[idx] ** 2
    x_true = np.array([truth[n] for n in names])
    pull = C @ (p_inv * (mu[idx] - x_true))
    c_data = np.diag(C) - np.einsum("ij,j,ji->i", C, p_inv, C)
    err = np.array([res.values[n] - truth[n] for n in names]) - pull
    return (err / np.sqrt(np.maximum(c_data, np.finfo(float).tiny))).tolist()


def summarise(root):
    """Print each case's figures from the files under ``root``."""
    for case in CASES:
        files = sorted((root / case).glob("seed-*.json"))
        if not files:
            continue
        runs = [json.loads(f.read_text()) for f in files]
        n = len(runs)
        print(f"\n== {case}: {n} seeds ({runs[0]['hours']} h records)")
        verdicts = sum(r["verdict"]["passed"] for r in runs)
        print(f"   verdict passed {verdicts} / {n}")
        for solver in runs[0]["solvers"]:
            names = runs[0]["solvers"][solver]["names"]
            z = np.array([r["solvers"][solver]["z"] for r in runs if r["solvers"][solver]["names"] == names])
            dominated = set().union(*(r["solvers"][solver]["prior_dominated"] for r in runs))
            cols = [i for i, nm in enumerate(names) if nm not in dominated]
            zd = z[:, cols]
            per_element = np.sqrt(np.mean(zd**2, axis=0))
            m = zd.shape[0]
            lo, hi = (math.sqrt(stats.chi2.ppf(q, m) / m) for q in (0.005 / len(cols), 1 - 0.005 / len(cols)))
            outside = [(names[cols[i]], round(float(v), 2)) for i, v in enumerate(per_element) if not lo <= v <= hi]
            kinds = {}
            for r in runs:
                for k, v in r["solvers"][solver]["kinds"].items():
                    if v["chi2_per_redundancy"] is not None:
                        kinds.setdefault(k, []).append(v["chi2_per_redundancy"])
            print(f"   {solver}: pooled RMS z {np.sqrt(np.mean(zd**2)):.3f} over {len(cols)} elements x {m} seeds; "
                  f"per element {per_element.min():.2f}..{per_element.max():.2f} "
                  f"(limits of {m} seeds at 1 % overall: {lo:.2f}..{hi:.2f}); within 3 sigma "
                  f"{100 * np.mean(np.abs(zd) < 3):.1f} %")
            if outside:
                print(f"      per-element RMS outside the limits: {outside}")
            zdat = [r["solvers"][solver].get("z_data") for r in runs if r["solvers"][solver]["names"] == names]
            if zdat and all(v is not None for v in zdat):
                zz = np.array(zdat)[:, cols]
                pe = np.sqrt(np.mean(zz**2, axis=0))
                out_d = [(names[cols[i]], round(float(v), 2)) for i, v in enumerate(pe) if not lo <= v <= hi]
                print(f"      data part (the prior's pull removed, data_part_z): pooled RMS {np.sqrt(np.mean(zz**2)):.3f}; "
                      f"per element {pe.min():.2f}..{pe.max():.2f}; outside the limits: {out_d or 'none'}")
            print("      chi2/redundancy: " + ", ".join(f"{k} {min(v):.3f}..{max(v):.3f}" for k, v in kinds.items()))
        ratios = {}
        for r in runs:
            sim = r["simulated_noise"]
            idn = r["solvers"][DEFAULT_SOLVERS[0]]["noise"] or {}
            q = math.sqrt(sim["gyro_noise"] ** 2 + 2 * sim.get("gyro_quantization_rad", 0.0) ** 2)
            for s, ref in (("gyro", q), ("accel", sim["accel_noise"])):
                d = (idn.get(s) or {}).get("density")
                if d:
                    ratios.setdefault(s, []).append(d / ref)
        print("   identified / simulated density: " + ", ".join(
            f"{s} {min(v):.3f}..{max(v):.3f}" for s, v in ratios.items()))
        print(f"   seconds per run: median {np.median([r['seconds'] for r in runs]):.1f}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--cases", default="clean", help=f"comma-separated, of {', '.join(CASES)}")
    p.add_argument("--seeds", type=seed_range, default=range(0, 20), help="A:B, the seeds A..B-1")
    p.add_argument("--hours", type=float, default=0.1)
    p.add_argument("--priors", choices=("grade", "truth"), default="grade",
                   help="grade: the product's priors (as calibrate); truth: the RMS of the simulator's truth draw")
    p.add_argument("--summary", action="store_true")
    args = p.parse_args(argv)
    if args.summary:
        summarise(args.out)
        return 0
    cases = cases_of(p, args.cases, CASES)
    run_resumable(args.out, [(c, s) for c in cases for s in args.seeds],
                  lambda case, seed: run_one(case, seed, hours=args.hours, priors=args.priors),
                  lambda case, seed, record: (f"{case} seed {seed}: verdict "
                                              f"{'pass' if record['verdict']['passed'] else 'FAIL'}, "
                                              f"{record['seconds']:.1f} s"))
    return 0

if __name__ == "__main__":
    sys.exit(main())
