"""The product beside imucal's closed-form Ferraris calibration on the simulator's Ferraris sessions."""

import numpy as np
import pytest

from graph_calib import io
from graph_calib.calibrate import calibrate
from graph_calib.cli import main
from graph_calib.compensation.calibration import Calibration
from graph_calib.evaluation.crossval import Fold, held_out_figures, make_folds, record_rests, training_record
from graph_calib.model import ModelOptions
from graph_calib.options import CalibrationOptions

from imucal_peer import imucal_ferraris

#: Comparative runs of whole sessions (several calibrations each): the slow tier.
pytestmark = pytest.mark.slow

CONSUMER = CalibrationOptions(model=ModelOptions(grade="consumer"))


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


@pytest.mark.parametrize("seed", [1, 2, pytest.param(3, marks=pytest.mark.xfail(strict=True, reason=(
    "one of its rests is detect_static's (a 1-2 s core) and holds no whole keyframe of the grid: it gets no static "
    "keyframe (keyframes are cut only at the short pass's rests, so that the measured sessions keep theirs), and "
    "in sample the transitions are 0.154 deg against imucal's 0.073 (0.030 when every rest without a keyframe is cut)")))])
def test_imucal_and_the_product_on_a_whole_hand_held_ferraris_session(seed):
    """Rests of 0.5-1.5 s, a swaying hand, a start in motion: every rest found, the gyro scales resolved."""
    exp, truth, rests = _short_rest_session(seed)
    assert rests.shape[0] == 12                     # six faces and the two rests of each full turn
    every = Fold(index=0, spans=((0, exp.n_samples),), rests=(rests,))
    run = calibrate(exp, options=CONSUMER, solvers=("factor-graph",))
    result = run.results["factor-graph"]
    fig = {name: held_out_figures(exp, every, cal) for name, cal in (
        ("raw", None), ("truth", truth), ("imucal", imucal_ferraris(exp, rests)),
        ("product", Calibration.from_result(result)))}
    # the gyro scales from the full turns between short rests, not the prior (consumer: 1e-2)
    assert all(result.sigmas[f"gyro.scale.{a}"] < 1e-3 for a in "xyz")
    assert fig["product"].transitions_rms_deg <= fig["imucal"].transitions_rms_deg
    assert fig["product"].static_norm_std_mps2 <= 1.2 * fig["imucal"].static_norm_std_mps2


@pytest.mark.xfail(strict=True, reason="issue 22, open: fitted on one of two folds of a six-face session (half the "
                   "faces and turns), the product's held-out transitions are 1-4 deg against imucal's 0.1-0.2 deg fitted "
                   "on the whole record; imucal's model takes each full turn to be exactly about a body axis, which "
                   "the simulator's hand does, and the product's rotation factors cannot see a turn's cross-axis terms")
def test_held_out_hand_held_ferraris_no_worse_than_imucal():
    exp, _, rests = _short_rest_session(1)
    peer = imucal_ferraris(exp, rests)
    for fold in make_folds(exp, folds=2, by="pairs", rests=rests):
        cal = Calibration.from_result(calibrate(training_record(exp, fold, rests=rests), options=CONSUMER,
                                                solvers=("factor-graph",)).results["factor-graph"])
        mine, theirs = held_out_figures(exp, fold, cal), held_out_figures(exp, fold, peer)
        assert mine.transitions_rms_deg <= theirs.transitions_rms_deg
        assert mine.static_norm_std_mps2 <= 1.2 * theirs.static_norm_std_mps2
