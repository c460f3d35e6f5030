"""The closed loop's round-1 score statistics on clean records, against their chi-square null (issue #21).

Each seed simulates ``nav-subrange-short`` for 0.4 h with exactly linear temperature curves (no effect the loop
should find), the true noise ``--noise-factor`` times the navigation grade's, table readings at
``--encoder-rate-hz`` with ``--encoder-noise-arcsec`` of noise, and runs the loop's first round as ``graph-calib
diagnose`` does (the grade chosen from the rests, the factor graph); it writes every candidate's statistic and
degrees of freedom to ``OUT/CASE/seed-NNNN.json``, ``CASE`` named by the options (``noise-3x_readings-10hz-2arcsec``;
a file that exists is not run again: ``_seed_study.run_resumable``). Under the null each statistic
is chi-square with its degrees of freedom: mean statistic over dof 1, a share 0.01 with p below 0.01.

``--summary OUT [OUT2]`` prints per candidate the mean statistic over dof with its standard error, the shares with
p below 0.05 and 0.01 and a Kolmogorov-Smirnov p; with two folders (the same seeds and options, two checkouts),
the paired difference of the means, which is far more precise than either mean.

Usage::

    python scripts/candidate_statistics.py --out /tmp/cs --seeds 0:130 --noise-factor 3
    python scripts/candidate_statistics.py --out /tmp/cs --seeds 0:130 --encoder-noise-arcsec 0.5
    python scripts/candidate_statistics.py --summary /tmp/cs-old/noise-3x_readings-10hz-2arcsec \
        /tmp/cs/noise-3x_readings-10hz-2arcsec

The random generator of a seed is ``numpy.random.default_rng(90_000 + seed)`` whatever the options, so two
folders of different options hold the same draws scaled.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy import stats

from graph_calib.diagnosis import DiagnosisOptions, diagnose
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions
from graph_calib.records.grade_choice import choose_grade
from graph_calib.simulation import simulate

from _seed_study import run_resumable, seed_range  # scripts/: run as a script, its folder on sys.path

SEED_BASE = 90_000


def run_one(seed, *, noise_factor, encoder_rate_hz, encoder_noise_arcsec):
    """Round-1 statistics of one clean record: ``{candidate: [statistic, dof]}`` with the grade and seconds."""
    t0 = time.perf_counter()
    se = simulate("nav-subrange-short", rng=np.random.default_rng(SEED_BASE + seed), hours=0.4, curvature=False,
                  noise_factor=noise_factor, encoder_rate_hz=encoder_rate_hz,
                  encoder_noise_arcsec=encoder_noise_arcsec).run()[0]
    choice = choose_grade(se.experiment)
    d = diagnose(se.experiment, options=CalibrationOptions(model=ModelOptions(grade=choice.grade)),
                 diagnosis=DiagnosisOptions(solvers=("factor-graph",), max_added=1))
    first = d.rounds[0]
    return {"seed": seed, "grade": choice.grade,
            "stats": {t.name: [float(t.statistic), int(t.dof)] for t in first.candidates if not t.skipped},
            "seconds": time.perf_counter() - t0}


def case_name(*, noise_factor, encoder_rate_hz, encoder_noise_arcsec):
    """The folder of a set of options: ``noise-3x_readings-10hz-2arcsec`` (``grade`` for the grade's noise)."""
    noise = "grade" if encoder_noise_arcsec is None else f"{encoder_noise_arcsec:g}"
    return f"noise-{noise_factor:g}x_readings-{encoder_rate_hz:g}hz-{noise}arcsec"


def _load(folder):
    return {p.name: json.loads(p.read_text())["stats"] for p in sorted(Path(folder).glob("seed-*.json"))}


def summarise(folders):
    runs = [_load(f) for f in folders]
    seeds = sorted(set.intersection(*(set(r) for r in runs)))
    print(f"{len(seeds)} records" + (" (paired)" if len(runs) == 2 else ""))
    names = sorted({n for s in seeds for n in runs[-1][s]})
    for n in names:
        have = [s for s in seeds if all(n in r[s] for r in runs)]
        if not have:
            continue
        dof = runs[-1][have[0]][n][1]
        line = f"  {n:22s} dof {dof}"
        T = []
        for r in runs:
            t = np.array([r[s][n][0] for s in have])
            d = np.array([r[s][n][1] for s in have])
            p = stats.chi2.sf(t, d)
            T.append(t / d)
            line += (f" | mean T/dof {np.mean(t / d):.3f} +- {np.sqrt(2.0 / dof / t.size):.3f}, p<.05 {np.mean(p < .05):.3f},"
                     f" p<.01 {np.mean(p < .01):.3f}, KS p {stats.kstest(p, 'uniform').pvalue:.2g}")
        if len(runs) == 2:
            diff = T[1] - T[0]
            line += f" | paired difference {diff.mean():+.3f} +- {diff.std(ddof=1) / np.sqrt(diff.size):.3f}"
        print(line)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path)
    ap.add_argument("--seeds", type=seed_range, default=range(0, 20), help="A:B, the seeds A..B-1")
    ap.add_argument("--noise-factor", type=float, default=1.0)
    ap.add_argument("--encoder-rate-hz", type=float, default=10.0)
    ap.add_argument("--encoder-noise-arcsec", type=float, default=None)
    ap.add_argument("--summary", nargs="+", type=Path, metavar="OUT")
    args = ap.parse_args(argv)
    if args.summary:
        summarise(args.summary)
        return 0
    if args.out is None:
        ap.error("--out is needed to run seeds")
    options = dict(noise_factor=args.noise_factor, encoder_rate_hz=args.encoder_rate_hz,
                   encoder_noise_arcsec=args.encoder_noise_arcsec)
    case = case_name(**options)
    run_resumable(args.out, [(case, seed) for seed in args.seeds], lambda _, seed: run_one(seed, **options),
                  lambda _, seed, out: f"{case} seed {seed}: {out['seconds']:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
