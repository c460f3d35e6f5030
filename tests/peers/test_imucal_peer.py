"""The product beside imucal's closed-form Ferraris calibration on the simulator's Ferraris sessions."""

import numpy as np
import pytest

from graph_calib import io
from graph_calib.calibrate import calibrate
from graph_calib.cli import main
from graph_calib.compensation.calibration import Calibration
from graph_calib.evaluation.crossval import (Fold, face_to_face_folds, held_out_figures, make_folds, record_rests,
                                             training_record)
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions

from imucal_peer import imucal_ferraris

#: Comparative runs of whole sessions (several calibrations each): the slow tier.
pytestmark = pytest.mark.slow

CONSUMER = CalibrationOptions(model=ModelOptions(grade="consumer"))
#: A hand-held session with short rests (README): the moving keyframes' gravity sigma estimated.
HAND_HELD = CalibrationOptions(model=ModelOptions(grade="consumer", moving_sigma="estimate"))


def _session(tmp_path, seed):
    assert main(["simulate", "consumer-ferraris", "--seed", str(seed), "--out", str(tmp_path)]) == 0
    exp = io.read_experiment(tmp_path / "ferraris.h5")
    return exp, Calibration.from_result(io.read_result(tmp_path / "ferraris.truth.json")), record_rests(exp)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_imucal_and_the_product_on_a_whole_ferraris_session(tmp_path, seed):
    exp, truth, rests = _session(tmp_path, seed)
    every = Fold(index=0, spans=((0, exp.n_samples),), rests=(rests,))
    fig = {name: held_out_figures(exp, every, cal) for name, cal in (
        ("raw", None), ("truth", truth), ("imucal", imucal_ferraris(exp, rests)),
        ("product", Calibration.from_result(calibrate(exp, options=CONSUMER, solvers=("factor-graph",))
                                            .results["factor-graph"])))}
    # the adapter is faithful: imucal removes nearly all of the raw error
    assert fig["imucal"].transitions_rms_deg < 0.05 * fig["raw"].transitions_rms_deg
    assert fig["imucal"].static_norm_std_mps2 < 0.05 * fig["raw"].static_norm_std_mps2
    # the product, fitted on the same record, at least as good as imucal
    assert fig["product"].transitions_rms_deg <= fig["imucal"].transitions_rms_deg
    assert fig["product"].static_norm_std_mps2 <= 1.2 * fig["imucal"].static_norm_std_mps2
    assert fig["product"].transitions_rms_deg < 2.0 * fig["truth"].transitions_rms_deg + 0.01


def test_held_out_rotations_are_predicted_by_the_calibration_fitted_without_them(tmp_path):
    exp, _, rests = _session(tmp_path, 2)
    for fold in make_folds(exp, folds=3, by="transitions", rests=rests):
        train = training_record(exp, fold, rests=rests)
        assert train.n_samples == exp.n_samples - sum(b - a for a, b in fold.spans)
        cal = Calibration.from_result(calibrate(train, options=CONSUMER, solvers=("factor-graph",))
                                      .results["factor-graph"])
        held, raw = held_out_figures(exp, fold, cal), held_out_figures(exp, fold)
        assert np.isnan(held.static_norm_std_mps2)            # every rest stayed in the training record
        assert held.transitions_rms_deg < 0.1 * raw.transitions_rms_deg


def _short_rest_session(seed):
    from graph_calib.simulation.scenarios import SHORT_REST_FERRARIS, simulate
    se = simulate("consumer-ferraris", rng=np.random.default_rng(seed), **SHORT_REST_FERRARIS).plans[0].make()
    exp = se.experiment
    return exp, Calibration.from_result(se.truth), record_rests(exp)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_imucal_and_the_product_on_a_whole_hand_held_ferraris_session(seed):
    """Rests of 0.5-1.5 s, a swaying hand, a start in motion: every rest found, the gyro scales resolved (the moving
    keyframes' gravity sigma estimated, as the README says for such a session; in sample, so without the sway term,
    which deweights the rests these figures are taken on)."""
    exp, truth, rests = _short_rest_session(seed)
    assert rests.shape[0] == 12                     # six faces and the two rests of each full turn
    every = Fold(index=0, spans=((0, exp.n_samples),), rests=(rests,))
    run = calibrate(exp, options=HAND_HELD, solvers=("factor-graph",))
    result = run.results["factor-graph"]
    fig = {name: held_out_figures(exp, every, cal) for name, cal in (
        ("raw", None), ("truth", truth), ("imucal", imucal_ferraris(exp, rests)),
        ("product", Calibration.from_result(result)))}
    # the gyro scales from the full turns between short rests, not the prior (consumer: 1e-2)
    assert all(result.sigmas[f"gyro.scale.{a}"] < 1e-3 for a in "xyz")
    assert fig["product"].transitions_rms_deg <= fig["imucal"].transitions_rms_deg
    assert fig["product"].static_norm_std_mps2 <= 1.2 * fig["imucal"].static_norm_std_mps2


#: The product's options for a swaying hand (README): the moving keyframes' gravity sigma and the sway at rest estimated.
SWAYING_HAND = CalibrationOptions(model=ModelOptions(grade="consumer", moving_sigma="estimate", sway_sigma="estimate"))


def _fold_fit(exp, fold, rests, options):
    return calibrate(training_record(exp, fold, rests=rests), options=options,
                     solvers=("factor-graph",)).results["factor-graph"]


@pytest.mark.xfail(strict=True, reason=(
    "the bar lies below the true calibration's own held-out figures: imucal is fitted on the whole record, the held-out "
    "parts included, and each full turn's gyro column comes from that turn alone; over seeds 1-10 (two folds each) the "
    "truth's held-out transitions are 0.139 deg rms against imucal's 0.132. The product (sway estimated) gives 0.432 deg "
    "and 1.14e-2 m/s^2 (imucal 9.4e-3); on seed 1 fold 1 0.153 deg against 0.109, 1.51e-2 m/s^2 against 4.8e-3. Most "
    "of the rest is the gyro scale about the held-out full turn's axis, which the fold's training record barely informs "
    "(scripts/turn_diagnosis.py). On the face-to-face motions alone, which neither fits, 0.167 deg against imucal's "
    "0.145 and the truth's 0.133 (scripts/handheld_vs_imucal.py --by faces, docs/crossval.md); with the rests declared "
    "still (--still-rests) 0.150 on the faces and 0.318 deg by pairs. There the product's accelerometer ties imucal's (with the "
    "true gyro 0.145 each); the gap is the gyro's misalignments, which imucal takes from its protocol (each full turn about "
    "a box axis, exact in the simulator) and the product does not assume (docs/crossval.md)"))
def test_held_out_hand_held_ferraris_no_worse_than_imucal():
    exp, _, rests = _short_rest_session(1)
    peer = imucal_ferraris(exp, rests)
    for fold in make_folds(exp, folds=2, by="pairs", rests=rests):
        cal = Calibration.from_result(_fold_fit(exp, fold, rests, SWAYING_HAND))
        mine, theirs = held_out_figures(exp, fold, cal), held_out_figures(exp, fold, peer)
        assert mine.transitions_rms_deg <= theirs.transitions_rms_deg
        assert mine.static_norm_std_mps2 <= 1.2 * theirs.static_norm_std_mps2


def test_imucal_fitted_on_the_held_out_turn_beats_the_true_calibration():
    """Why the bar above is out of reach: imucal, fitted on the held-out parts too, goes below the truth there."""
    exp, truth, rests = _short_rest_session(3)
    peer = imucal_ferraris(exp, rests)
    fold = make_folds(exp, folds=2, by="pairs", rests=rests)[0]
    theirs, true = held_out_figures(exp, fold, peer), held_out_figures(exp, fold, truth)
    assert theirs.transitions_rms_deg < 0.85 * true.transitions_rms_deg         # 0.035 against 0.047 deg


def test_the_sway_term_makes_a_hand_held_fold_s_gyro_scales_honest():
    """A swaying hand unmodelled makes the rests' gravity factors overconfident: seed 4, fold 1 puts the trained full
    turn's gyro.scale.x 7.9 sigma off (held-out transitions 0.62 deg); with the sway estimated every gyro scale is within
    2 sigma and the held-out transitions are 0.31 deg."""
    exp, truth, rests = _short_rest_session(4)
    fold = make_folds(exp, folds=2, by="pairs", rests=rests)[0]
    swayed = _fold_fit(exp, fold, rests, SWAYING_HAND)
    still = _fold_fit(exp, fold, rests, HAND_HELD)
    true = truth.values()
    z = [(swayed.values[f"gyro.scale.{a}"] - true[f"gyro.scale.{a}"]) / swayed.sigmas[f"gyro.scale.{a}"] for a in "xyz"]
    assert np.max(np.abs(z)) < 3.0
    mine, before = (held_out_figures(exp, fold, Calibration.from_result(r)) for r in (swayed, still))
    assert mine.transitions_rms_deg < 0.7 * before.transitions_rms_deg


def _guided_session(seed):
    from graph_calib.simulation.scenarios import GUIDED_FERRARIS, simulate
    made = simulate("consumer-ferraris", rng=np.random.default_rng(seed), **GUIDED_FERRARIS).plans[0].make()
    return made.experiment, made.truth


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_guided_turns_inform_the_gyro_within_its_sigmas_and_both_solvers_agree(seed):
    """imucal's protocol (each full turn about the axis that is up, slid flat against a guide): the product finds the
    three turns and uses their closure and flatness; every gyro and accelerometer element within 3.5 sigma of the
    truth, no gyro sigma larger than with the turns taken for motion (but for the variance components' 2 %), the two
    solvers agreeing.  (On the whole record
    the faces' transitions already hold the gyro to 0.04 %; a closure of 0.5 deg over 360 deg adds 0.14 %: the turns
    matter where the transitions are few, below.)"""
    exp, truth = _guided_session(seed)
    run = calibrate(exp, options=CONSUMER)
    assert run.verdict.agree and run.verdict.max_difference_sigma < 0.1
    guided = run.results["factor-graph"]
    assert guided.extra["noise"]["guided_turns"]["count"] == 3
    off = calibrate(exp, options=CalibrationOptions(model=ModelOptions(grade="consumer", guided_turns=False)),
                    solvers=("factor-graph",)).results["factor-graph"]
    z = [(guided.values[k] - truth.values[k]) / guided.sigmas[k] for k in guided.values
         if k.startswith(("gyro.", "accel.")) and "_tc" not in k]
    assert np.max(np.abs(z)) < 3.5
    for k in guided.sigmas:
        if k.startswith("gyro."):          # the variance components of the two may differ by a little
            assert guided.sigmas[k] <= 1.02 * off.sigmas[k]


def test_guided_turns_predict_the_held_out_face_to_face_turns():
    """Every rest and full turn kept, the turns between faces held out (neither imucal nor the product fits them):
    seeds 1-3, two folds each. Measured: the turns taken for motion 1.45 deg rms, guided 0.088 deg; imucal 0.047, the
    truth 0.020 (imucal's box axes, exact in the simulator, give it the misalignments the product estimates from the
    faces' transitions)."""
    rows = []
    for seed in (1, 2, 3):
        exp, truth = _guided_session(seed)
        rests = record_rests(exp)
        for fold in face_to_face_folds(exp, folds=2, rests=rests):
            train = training_record(exp, fold, rests=rests)
            fig = []
            for guided in (False, True):
                options = CalibrationOptions(model=ModelOptions(grade="consumer", guided_turns=guided))
                r = calibrate(train, options=options, solvers=("factor-graph",)).results["factor-graph"]
                fig.append(held_out_figures(exp, fold, Calibration.from_result(r)).transitions_rms_deg)
            rows.append(fig)
    off, guided = np.sqrt(np.mean(np.square(rows), axis=0))
    assert guided < 0.1 * off
    assert np.all(np.array(rows)[:, 1] < 0.2)
