"""Which calibration elements cause the product's held-out transition error on hand-held Ferraris sessions.

For each seed's :data:`graph_calib.simulation.scenarios.SHORT_REST_FERRARIS` session and each of two folds (by pairs),
the product is fitted on the training record (``calibrate``, factor graph, consumer grade, the moving sigma estimated,
and the hand's sway unless ``--sway-sigma none``, as ``scripts/handheld_vs_imucal.py``); then groups of its elements
are replaced by the truth's and the held-out transition rms and |f| spread recomputed. Besides fixed groups: the gyro
scale (and the whole gyro-matrix column: the scale and the two cross-axis terms a turn about that axis drives) of the
axes whose full turn the training record holds (the most any use of a known full turn in the training record could
give) and of the axes whose full turn is held out. Also prints, per gyro element, the product's error against its
sigma.

    PYTHONPATH=$PWD python scripts/turn_diagnosis.py --seeds 1 2 3 [--sway-sigma none] [--still-rests] [--by faces]

``--by faces`` holds out the face-to-face motions alone (:func:`graph_calib.evaluation.crossval.face_to_face_folds`:
every full turn stays in training); ``--still-rests`` declares the rests still (``ModelOptions.still_at_rest``).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "peers"))

from imucal_peer import imucal_ferraris  # noqa: E402

from graph_calib.calibrate import calibrate  # noqa: E402
from graph_calib.compensation.calibration import Calibration  # noqa: E402
from graph_calib.evaluation.crossval import (face_to_face_folds, held_out_figures, make_folds, record_rests,  # noqa: E402
                                             training_record)
from graph_calib.simulation.scenarios import SHORT_REST_FERRARIS, simulate  # noqa: E402

from handheld_vs_imucal import product_options, sway_option  # noqa: E402

#: Groups of elements replaced by the truth's (prefixes of flat element names).
GROUPS = {
    "gyro.bias": ("gyro.bias.",),
    "gyro.scale": ("gyro.scale.",),
    "gyro.misalignment": ("gyro.misalignment.",),
    "gyro scale+misalignment": ("gyro.scale.", "gyro.misalignment."),
    "gyro (all)": ("gyro.",),
    "accel (all)": ("accel.",),
    "everything": ("",),
}


def mixed(product, truth, prefixes):
    """The product's calibration with the elements named by ``prefixes`` taken from ``truth``."""
    values = dict(product.values)
    for k, v in truth.values.items():
        if any(k.startswith(p) for p in prefixes):
            values[k] = v
    return Calibration.from_values(values, t_ref_degC=product.t_ref_degC,
                                   parameters=tuple(set(product.effects) | set(truth.effects)))


def full_turns(experiment, rests):
    """``{transition index: body axis 'x'|'y'|'z'}`` of the full turns: the raw angle between two rests over 300 deg."""
    out = {}
    for i, ((_, b), (a, _)) in enumerate(zip(rests[:-1], rests[1:])):
        angle = experiment.dtheta[b:a].sum(axis=0)
        k = int(np.argmax(np.abs(angle)))
        if abs(angle[k]) > np.radians(300.0):
            out[i] = "xyz"[k]
    return out


def held_transitions(fold, rests):
    """Indices ``i`` (rest ``i`` to rest ``i + 1``) of the transitions a fold holds out."""
    held = set()
    for r in fold.rests:
        i0 = int(np.flatnonzero(rests[:, 0] == r[0, 0])[0])
        held |= {i0 + j for j in range(r.shape[0] - 1)}
    return held


def column(axes, *, whole):
    """Element prefixes of the gyro scale about ``axes`` (``whole``: and the cross-axis terms of their column)."""
    out = tuple(f"gyro.scale.{a}" for a in axes)
    if whole:
        out += tuple(f"gyro.misalignment.{b}{a}" for a in axes for b in "xyz" if b != a)
    return out or ("-",)


def gyro_matrix(cal):
    """The gyro matrix ``A`` of a calibration (measured rate = ``A omega`` + bias, at its reference temperature)."""
    zero = np.zeros((1, 3))
    e0 = cal.sensor_errors(zero, zero, dT=np.zeros(6))[0][0]
    return np.eye(3) + np.stack([cal.sensor_errors(np.eye(3)[k:k + 1], zero, dT=np.zeros(6))[0][0] - e0
                                 for k in range(3)], axis=1)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--sway-sigma", type=sway_option, default="estimate",
                   help="the product's sway sigma: 'estimate' (default), 'none' or m/s^2")
    p.add_argument("--by", choices=("pairs", "faces"), default="pairs",
                   help="folds by pairs of rests, or the face-to-face motions alone")
    p.add_argument("--still-rests", action="store_true", help="the product's rests still (ModelOptions.still_at_rest)")
    args = p.parse_args(argv)
    options = product_options(sway=args.sway_sigma, still=args.still_rests)
    turn_groups = ("trained turns' scales", "trained turns' columns", "held-out turns' scales",
                   "held-out turns' columns")
    rows = {name: [] for name in ("raw", "imucal", "product", *GROUPS, *turn_groups)}
    for seed in args.seeds:
        se = simulate("consumer-ferraris", rng=np.random.default_rng(seed), tag=f"seed {seed}",
                      **SHORT_REST_FERRARIS).plans[0].make()
        exp, truth = se.experiment, se.truth
        rests = record_rests(exp)
        peer = imucal_ferraris(exp, rests)
        turns = full_turns(exp, rests)
        folds = (face_to_face_folds(exp, folds=2, rests=rests) if args.by == "faces"
                 else make_folds(exp, folds=2, by="pairs", rests=rests))
        for fold in folds:
            held = held_transitions(fold, rests)
            trained = tuple(a for i, a in turns.items() if i not in held)
            out = tuple(a for i, a in turns.items() if i in held)
            res = calibrate(training_record(exp, fold, rests=rests), options=options,
                            solvers=("factor-graph",)).results["factor-graph"]
            cals = {"raw": None, "imucal": peer, "product": Calibration.from_result(res)}
            cals.update({name: mixed(res, truth, pre) for name, pre in GROUPS.items()})
            for name, axes, whole in zip(turn_groups, (trained, trained, out, out), (False, True, False, True)):
                cals[name] = mixed(res, truth, column(axes, whole=whole))
            line = []
            for name, cal in cals.items():
                f = held_out_figures(exp, fold, cal)
                rows[name].append((f.transitions_rms_deg, f.static_norm_std_mps2))
                line.append(f"{name}={f.transitions_rms_deg:.3f}deg/{f.static_norm_std_mps2:.1e}")
            print(f"seed {seed} fold {fold.index + 1} (full turns trained {''.join(trained) or '-'}, held out "
                  f"{''.join(out) or '-'}): " + "  ".join(line), flush=True)
            z = {k: (res.values[k] - truth.values.get(k, 0.0)) / res.sigmas[k] for k in res.values
                 if k.startswith("gyro.") and res.sigmas.get(k)}
            off = ~np.eye(3, dtype=bool)
            A_true = gyro_matrix(Calibration.from_result(truth))
            print("   gyro matrix off-diagonal error, 1e-3: product "
                  + " ".join(f"{v:+.3f}" for v in 1e3 * (gyro_matrix(cals["product"]) - A_true)[off])
                  + ", imucal " + " ".join(f"{v:+.3f}" for v in
                                          1e3 * (np.asarray(peer.info.K_g) @ np.asarray(peer.info.R_g) - A_true)[off]),
                  flush=True)
            print("   gyro error/sigma: " + " ".join(
                f"{k[5:]}={res.values[k] - truth.values.get(k, 0.0):+.1e}({v:+.1f}s)" for k, v in z.items()),
                flush=True)
    print(f"{'pooled over seeds ' + ' '.join(map(str, args.seeds)):<40} {'transitions rms deg':>20} {'|f| spread':>12}")
    for name, r in rows.items():
        with warnings.catch_warnings():     # --by faces holds out no rest: the |f| column is all NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            a = np.sqrt(np.nanmean(np.asarray(r, dtype=float) ** 2, axis=0))
        print(f"{name:<40} {a[0]:>20.3f} {a[1]:>12.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
