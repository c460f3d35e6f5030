"""The method's headline claim as a study: continuous temperature profile against constant-temperature steps.

Same simulated navigation-grade IMU, same turntable programme design, same solver (the factor graph; the
filter gives the same estimates), same stitching and validation:

traditional
    seven steps at -10, 0, ..., +50 degC; at each the IMU is first soaked until its sensors settle
    (``SOAK_H`` hours per 10 degC step, not recorded), then calibrated for ``L`` hours at constant
    temperature (temperature coefficients are not observable there and are left out of the model);
    the seven values are stitched over temperature.  Duration ``7 L + 6 SOAK_H``.
continuous
    six subranges of 10 degC, the chamber ramping all the time (the ``nav-campaign`` design, sensors
    drifting 8 degC per subrange); each subrange estimates values and temperature coefficients; stitched.
    Duration ``6 L``.

The initial soak at -10 degC is the same for both and is not counted.  Accuracy: the validation of
``graph_calib.evaluation.validation`` on one independent 3 h record sweeping -10..+50 degC (largest remaining gyro
error at rest, largest accelerometer error), averaged over ``--seeds`` noise realisations.

Run (about 20-40 min on 2 cores; results are cached in ``--work`` and reused)::

    .venv/bin/python scripts/study_profiles.py [--seeds 3] [--work /tmp/study-profiles] [--quick]

Writes ``docs/figures/study_profiles.png``, ``docs/figures/study_curves.png`` and
``docs/figures/study_profiles.json`` (the numbers quoted in docs/study.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Soak before each traditional step, h (about four time constants of the slowest sensor, 35-38 min:
#: the sensors within 2 % of a 10 degC step, 0.2 degC).
SOAK_H = 2.5
#: Step temperatures of the traditional profile, degC.
STEPS_DEGC = (-10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0)
#: Subranges of the continuous profile (those of the nav-campaign scenario), degC.
SUBRANGES = ((-10.0, 0.0), (0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, 40.0), (40.0, 50.0))
#: Recorded hours per experiment, per profile.
LENGTHS_H = {"traditional": (0.25, 0.5, 1.0, 2.0), "continuous": (0.25, 0.5, 1.0, 2.0, 3.0)}
QUICK_LENGTHS_H = {"traditional": (0.25, 1.0), "continuous": (0.25, 1.0)}
IMU_SEED = 2024
TC_PARAMS = ("gyro.bias_tc", "gyro.scale_tc", "accel.bias_tc", "accel.scale_tc")


def _simulation(hours=1.0):
    from graph_calib.simulation import simulate

    return simulate("nav-campaign", rng=np.random.default_rng(IMU_SEED), hours=hours)


def duration_h(profile, L):
    return 6 * L if profile == "continuous" else len(STEPS_DEGC) * L + (len(STEPS_DEGC) - 1) * SOAK_H


def jobs(seeds, lengths):
    out = []
    for seed in seeds:
        for L in lengths["continuous"]:
            for k, (lo, hi) in enumerate(SUBRANGES):
                out.append(("continuous", L, seed, k, lo + 1.0, 8.0))
        for L in lengths["traditional"]:
            for k, T in enumerate(STEPS_DEGC):
                out.append(("traditional", L, seed, k, T, 0.0))
    return out


def job_path(work, job):
    profile, L, seed, k, _, _ = job
    return Path(work) / "results" / f"{profile}_L{L:g}_s{seed}_{k}.json"


def run_job(job, work):
    """Simulate one experiment, calibrate it (factor graph), write its result and sensor ranges."""
    import numba

    numba.set_num_threads(1)
    from graph_calib import io
    from graph_calib.calibrate import CalibrationOptions, build_problem, solve_problem
    from graph_calib.model import ModelOptions
    from graph_calib.evaluation.validation import simulate_validation_record

    profile, L, seed, k, start, span = job
    path = job_path(work, job)
    if path.is_file():
        return str(path), 0.0
    t0 = time.perf_counter()
    sim = _simulation()
    se = simulate_validation_record(sim, hours=L, start_degC=start, span_degC=span,
                                    seed=int(1_000_003 * seed + 7919 * k + int(L * 1000) + (0 if profile ==
                                                                                             "continuous" else 17)),
                                    file_name=f"{profile}_{k}.h5")
    exclude = TC_PARAMS if profile == "traditional" else ()
    opts = CalibrationOptions(model=ModelOptions(exclude=exclude))
    problem = build_problem(se.experiment, options=opts)
    res = solve_problem(problem, options=opts, solvers=("factor-graph",)).results["factor-graph"]
    T = se.experiment.sensor_temperatures()
    doc = {"result": io.result_to_dict(res), "ranges": np.stack([T.min(0), T.max(0)], 1).tolist()}
    path.parent.mkdir(parents=True, exist_ok=True)
    io.atomic_write_json(path, doc)
    return str(path), time.perf_counter() - t0


def _load(path):
    from graph_calib import io

    doc = json.loads(Path(path).read_text())
    tmp = Path(path).with_suffix(".result.json")
    if not tmp.is_file():
        io.atomic_write_json(tmp, doc["result"])
    return io.read_result(tmp), doc["ranges"]


def validation_record(work):
    from graph_calib import io
    from graph_calib.evaluation.validation import simulate_validation_record

    rec = Path(work) / "validation.h5"
    if not rec.is_file():
        se = simulate_validation_record(_simulation(), hours=3.0, rate_hz=20.0, seed=99)
        io.write_experiment(se.experiment, rec)
        io.write_result(se.truth, Path(work) / "validation.truth.json")
    return rec


def evaluate(work, seeds, lengths):
    from graph_calib import constants as c
    from graph_calib import io
    from graph_calib.stitching import stitch
    from graph_calib.evaluation.validation import ResultCalibration, validate, window_means

    rec = validation_record(work)
    exp = io.read_experiment(rec)
    w = window_means(exp)
    truth = ResultCalibration(io.read_result(Path(work) / "validation.truth.json"))
    rows = []
    stitched_examples = {}
    for profile in ("traditional", "continuous"):
        n = len(STEPS_DEGC) if profile == "traditional" else len(SUBRANGES)
        for L in lengths[profile]:
            per_seed = []
            for seed in seeds:
                loaded = [_load(job_path(work, (profile, L, seed, k, 0, 0))) for k in range(n)]
                st = stitch([r for r, _ in loaded], names=[f"{profile}{k}" for k in range(n)],
                            sensor_ranges=[rg for _, rg in loaded], solver="factor-graph")
                s = validate(exp, st, truth, model="cubic", windows=w).summary()
                g = s["gyro_radps"]["static"]
                a = s["accel_mps2"]["all"]
                per_seed.append([max(g["max"]) * c.RS_TO_DH, float(np.sqrt(np.mean(np.square(g["rms"])))) * c.RS_TO_DH,
                                 max(a["max"]), float(np.sqrt(np.mean(np.square(a["rms"]))))])
                if seed == seeds[0]:
                    stitched_examples[(profile, L)] = st
            m = np.array(per_seed)
            rows.append({"profile": profile, "L_h": L, "duration_h": duration_h(profile, L),
                         "gyro_max_dph": float(m[:, 0].mean()), "gyro_rms_dph": float(m[:, 1].mean()),
                         "accel_max_mps2": float(m[:, 2].mean()), "accel_rms_mps2": float(m[:, 3].mean()),
                         "gyro_max_dph_seeds": m[:, 0].tolist(), "accel_max_mps2_seeds": m[:, 2].tolist()})
    return rows, stitched_examples, truth


def equivalent_duration(rows, key):
    """For each traditional point: the continuous duration reaching the same accuracy.

    Log-log interpolation along the continuous points (made monotone: the best accuracy reached so far).
    ``bound`` is ``"at most"`` when even the shortest continuous campaign is as good (the duration given
    is that shortest one), ``"not reached"`` when no continuous campaign measured is as good.
    """
    cont = sorted((r for r in rows if r["profile"] == "continuous"), key=lambda r: r["duration_h"])
    d = np.log([r["duration_h"] for r in cont])
    env = np.minimum.accumulate(np.log([r[key] for r in cont]))
    out = []
    for r in (r for r in rows if r["profile"] == "traditional"):
        target = np.log(r[key])
        if target >= env[0]:
            dur, bound = float(np.exp(d[0])), "at most"
        elif target < env[-1]:
            dur, bound = float("nan"), "not reached"
        else:
            j = int(np.argmax(env <= target))
            f = (target - env[j - 1]) / (env[j] - env[j - 1]) if env[j] != env[j - 1] else 1.0
            dur, bound = float(np.exp(d[j - 1] + f * (d[j] - d[j - 1]))), "about"
        out.append({"L_h": r["L_h"], "traditional_h": r["duration_h"], "continuous_h": dur, "bound": bound,
                    "ratio": dur / r["duration_h"] if np.isfinite(dur) else float("nan")})
    return out


def figures(rows, examples, truth, outdir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from graph_calib import constants as c

    outdir.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for profile, color, marker in (("traditional", "#d62728", "s"), ("continuous", "#1f77b4", "o")):
        rr = sorted((r for r in rows if r["profile"] == profile), key=lambda r: r["duration_h"])
        D = [r["duration_h"] for r in rr]
        for ax, key, rms_key, k in ((axes[0], "gyro_max_dph", "gyro_rms_dph", 1.0),
                                    (axes[1], "accel_max_mps2", "accel_rms_mps2", c.MPS2_TO_UG)):
            ax.plot(D, [r[key] * k for r in rr], marker + "-", color=color, label=f"{profile}: largest error")
            ax.plot(D, [r[rms_key] * k for r in rr], marker + ":", color=color, mfc="none", label=f"{profile}: rms")
            for r in rr:
                ax.annotate(f"{r['L_h']:g} h", (r["duration_h"], r[key] * k), textcoords="offset points",
                            xytext=(4, 4), fontsize=7, color=color)
    axes[0].axhline(0.01, color="k", ls="--", lw=1, label="published accuracy 0.01 deg/h")
    axes[1].axhline(2e-4 * c.MPS2_TO_UG, color="k", ls="--", lw=1, label="published accuracy 2e-4 m/s^2")
    axes[0].set_ylabel("remaining gyro error at rest, deg/h")
    axes[1].set_ylabel("remaining accelerometer error, micro-g")
    from matplotlib.ticker import FuncFormatter

    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
        ax.xaxis.set_minor_formatter(FuncFormatter(lambda x, _: f"{x:g}" if str(f"{x:g}")[0] in "25" else ""))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
        ax.set_xlabel("campaign duration, h (soaks included, initial soak excluded)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle("Accuracy against campaign duration: continuous temperature profile vs constant-temperature "
                 "steps (labels: recorded hours per experiment)", fontsize=10)
    fig.tight_layout()
    fig.savefig(outdir / "study_profiles.png", dpi=110)
    plt.close(fig)

    # the stitched gyro bias of both profiles at a comparable duration
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.0), sharey=True)
    L = 1.0 if ("traditional", 1.0) in examples else sorted({k[1] for k in examples})[0]
    for ax, profile in zip(axes, ("traditional", "continuous")):
        st = examples[(profile, L)]
        for i, a in enumerate("xyz"):
            cv = st.curves[f"gyro.bias.{a}"]
            lo, hi = cv.t_span
            T = np.linspace(min(lo, -10.0), max(hi, 50.0), 240)
            tv = truth.evaluate(np.tile(T[:, None], (1, 6)))[cv.element]
            v, s = cv.evaluate(T, "cubic")
            col = ("#1f77b4", "#2ca02c", "#d62728")[i]
            inside = (T >= lo) & (T <= hi)
            ax.plot(T[inside], (v - tv)[inside] * c.RS_TO_DH, "-", color=col, label=f"gyro {a}")
            for part in (T < lo, T > hi):
                if np.any(part):
                    ax.plot(T[part], (v - tv)[part] * c.RS_TO_DH, ":", color=col, lw=1)
            ax.fill_between(T[inside], (v - s - tv)[inside] * c.RS_TO_DH, (v + s - tv)[inside] * c.RS_TO_DH,
                            color=col, alpha=0.15, lw=0)
            for p in cv.points:
                t0 = p.t_ref_degC
                tv0 = truth.evaluate(np.full((1, 6), t0))[cv.element][0]
                ax.errorbar([t0], [(p.value - tv0) * c.RS_TO_DH], yerr=[p.sigma * c.RS_TO_DH], fmt="o", ms=3,
                            color=col, capsize=2)
        ax.axhline(0.0, color="k", lw=0.8)
        for y in (-0.01, 0.01):
            ax.axhline(y, color="k", ls="--", lw=0.8)
        ax.set_title(f"{profile}: {L:g} h per experiment, campaign {duration_h(profile, L):g} h", fontsize=9)
        ax.set_xlabel("sensor temperature, degC")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("stitched gyro bias minus truth, deg/h")
    fig.suptitle("One noise realisation; bands: stitched one sigma; dotted: outside the range the sensor was "
                 "calibrated over", fontsize=9)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(outdir / "study_curves.png", dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--work", default="/tmp/study-profiles")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="one seed, two lengths (a smoke run)")
    ap.add_argument("--figures", default=str(ROOT / "docs" / "figures"))
    args = ap.parse_args(argv)
    seeds = [1] if args.quick else list(range(1, args.seeds + 1))
    lengths = QUICK_LENGTHS_H if args.quick else LENGTHS_H
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    todo = [j for j in jobs(seeds, lengths) if not job_path(work, j).is_file()]
    print(f"{len(todo)} calibrations to run ({len(jobs(seeds, lengths)) - len(todo)} cached in {work})", flush=True)
    validation_record(work)
    t0 = time.perf_counter()
    if todo:
        # longest first, for an even load
        todo.sort(key=lambda j: -j[1])
        import multiprocessing

        # spawn: the main process has already used numba's OpenMP threads, which fork would break
        with ProcessPoolExecutor(max_workers=args.workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            futs = {pool.submit(run_job, j, str(work)): j for j in todo}
            for i, f in enumerate(as_completed(futs), 1):
                path, sec = f.result()
                print(f"  [{i}/{len(todo)}] {Path(path).stem} {sec:.0f} s ({time.perf_counter() - t0:.0f} s)",
                      flush=True)
    rows, examples, truth = evaluate(work, seeds, lengths)
    eq_g = equivalent_duration(rows, "gyro_max_dph")
    eq_r = equivalent_duration(rows, "gyro_rms_dph")
    eq_a = equivalent_duration(rows, "accel_max_mps2")
    figures(rows, examples, truth, Path(args.figures))
    doc = {"soak_h": SOAK_H, "steps_degC": STEPS_DEGC, "subranges_degC": SUBRANGES, "lengths_h": lengths,
           "seeds": seeds, "rows": rows, "equivalent_continuous_duration": {"gyro_max": eq_g, "gyro_rms": eq_r, "accel_max": eq_a}}
    Path(args.figures).mkdir(parents=True, exist_ok=True)
    (Path(args.figures) / "study_profiles.json").write_text(json.dumps(doc, indent=1))
    print("\n| profile | h per experiment | campaign h | gyro max, deg/h | gyro rms, deg/h | accel max, m/s^2 |")
    print("| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['profile']} | {r['L_h']:g} | {r['duration_h']:g} | {r['gyro_max_dph']:.4f} | "
              f"{r['gyro_rms_dph']:.4f} | {r['accel_max_mps2']:.2e} |")
    print("\ncontinuous duration reaching each traditional point's accuracy:")
    for g, gr, a in zip(eq_g, eq_r, eq_a):
        print(f"  traditional {g['L_h']:g} h/step ({g['traditional_h']:g} h): gyro max {g['bound']} "
              f"{g['continuous_h']:.2f} h (ratio {g['ratio']:.2f}), gyro rms {gr['bound']} {gr['continuous_h']:.2f} h "
              f"(ratio {gr['ratio']:.2f}), accel {a['bound']} {a['continuous_h']:.2f} h (ratio {a['ratio']:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
