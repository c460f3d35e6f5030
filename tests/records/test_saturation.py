"""A saturated gyro: the record cut after each episode (graph_calib.records.saturation)."""

import dataclasses

import numpy as np
import pytest

from graph_calib.calibrate import calibrate
from graph_calib.errors import InputError
from graph_calib.model import ModelOptions
from graph_calib.model.record import PreparedRecord
from graph_calib.options import CalibrationOptions
from graph_calib.records.saturation import cut_at_saturation, flat_tops, saturated_rates, saturation_note
from graph_calib.simulation.scenarios import simulate

CONSUMER = CalibrationOptions(model=ModelOptions(grade="consumer"))
#: A range below the fastest turn of consumer-ferraris seed 2 (its z turn peaks at 187 deg/s): one episode.
RANGE_RPS = np.radians(175.0)


@pytest.fixture(scope="module")
def clipped():
    """A simulated Ferraris session whose gyro output stops at RANGE_RPS, with its truth."""
    se = simulate("consumer-ferraris", rng=np.random.default_rng(2)).plans[0].make()
    exp = se.experiment
    w = np.clip(exp.dtheta / exp.dt[:, None], -RANGE_RPS, RANGE_RPS)
    return dataclasses.replace(exp, dtheta=w * exp.dt[:, None]), se.truth


def _z(result, truth):
    keys = [k for k in result.values if k in truth.values and result.sigmas[k] > 0]
    return np.array([(result.values[k] - truth.values[k]) / result.sigmas[k] for k in keys])


def test_a_saturated_turn_spoils_the_calibration_and_the_cut_restores_it(clipped):
    """Fitted across the lost angle the gyro scale is 23 sigma off and the rotation kind needs a factor of about
    1600 (the verdict fails); cut, every element is within 3.5 sigma of the truth and the verdict passes."""
    exp, truth = clipped
    cuts = cut_at_saturation(exp, saturated_rates(exp, gyro_range_rps=RANGE_RPS))
    assert cuts.episodes.shape[0] == 1 and cuts.cut.all() and cuts.experiment.n_segments == 2
    whole = calibrate(exp, options=CONSUMER, solvers=("factor-graph",))
    assert not whole.verdict.passed
    assert whole.verdict.kinds["factor-graph"]["rotation"]["variance_factor"] > 100.0
    assert np.abs(_z(whole.results["factor-graph"], truth)).max() > 10.0
    run = calibrate(cuts.experiment, options=CONSUMER, solvers=("factor-graph",))
    assert run.verdict.passed, run.verdict.problems
    z = _z(run.results["factor-graph"], truth)
    assert np.abs(z).max() < 3.5 and np.sqrt(np.mean(z**2)) < 1.3


def test_the_episode_lies_in_its_segment_s_last_keyframe_which_has_no_rotation_factor(clipped):
    exp, _ = clipped
    cuts = cut_at_saturation(exp, saturated_rates(exp, gyro_range_rps=RANGE_RPS))
    (a, b), = cuts.episodes
    assert cuts.experiment.segment_bounds()[0][1] == b           # the boundary on the first sample after it
    rec = PreparedRecord(cuts.experiment, keyframe_s=1.0)
    keys = np.unique(np.searchsorted(rec.k0, np.arange(a, b), side="right") - 1)
    assert keys.size == 1 and keys[0] not in rec.rotation_keys
    whole = PreparedRecord(exp, keyframe_s=1.0)
    assert np.isin(np.searchsorted(whole.k0, np.arange(a, b), side="right") - 1, whole.rotation_keys).any()


def test_an_episode_with_no_rest_after_it_is_kept_and_said(clipped):
    """A second episode 0.6 s before the first, in the same turn: a cut after it would leave a piece without a
    rest to align, so it is kept (and said); the later one is cut."""
    exp, _ = clipped
    sat = saturated_rates(exp, gyro_range_rps=RANGE_RPS)
    a = int(np.flatnonzero(sat)[0])
    early = sat.copy()
    early[a - 60] = True
    cuts = cut_at_saturation(exp, early)
    assert cuts.episodes[:, 0].tolist() == [a - 60, a] and cuts.cut.tolist() == [False, True]
    assert cuts.experiment.n_segments == 2
    note = saturation_note(cuts.experiment.description)
    assert note.startswith("The gyros are saturated in ") and f"those starting at {a - 60} are kept" in note


def test_runs_closer_than_the_episode_gap_are_one_episode_and_cutting_again_changes_nothing(clipped):
    exp, _ = clipped
    sat = saturated_rates(exp, gyro_range_rps=RANGE_RPS)
    a = int(np.flatnonzero(sat)[0])
    split = sat.copy()
    split[a + 2:a + 4] = False                       # a turn whose rate dips below the range for two samples
    once = cut_at_saturation(exp, split)
    assert once.episodes.shape[0] == 1 and once.samples == int(split.sum())
    twice = cut_at_saturation(once.experiment, split)
    np.testing.assert_array_equal(twice.experiment.segment, once.experiment.segment)
    assert twice.experiment.description.count("The gyros are saturated") == 1 and twice.cut.all()


def test_a_record_without_saturated_samples_is_returned_unchanged(clipped):
    exp, _ = clipped
    cuts = cut_at_saturation(exp, np.zeros(exp.n_samples, dtype=bool))
    assert cuts.experiment is exp and cuts.describe() == "" and saturation_note(exp.description) is None


def test_a_mask_of_another_length_is_refused(clipped):
    exp, _ = clipped
    with pytest.raises(InputError, match=f"the saturation mask has 10 samples, the record {exp.n_samples}"):
        cut_at_saturation(exp, np.zeros(10, dtype=bool))


@pytest.mark.parametrize("value", [0.0, -1.0, np.nan])
def test_a_range_that_is_not_positive_is_refused(clipped, value):
    with pytest.raises(InputError, match="the gyro range must be a positive number"):
        saturated_rates(clipped[0], gyro_range_rps=value)


def test_held_out_transitions_skip_the_one_across_a_saturated_turn(clipped):
    """IMU-TK's transition across the cut compares attitudes the record no longer links: not judged. The true
    calibration then predicts every judged transition; on the record kept whole the lost angle dominates."""
    from graph_calib.compensation.calibration import Calibration
    from graph_calib.evaluation.crossval import Fold, held_out_figures, record_rests

    exp, truth = clipped
    cut = cut_at_saturation(exp, saturated_rates(exp, gyro_range_rps=RANGE_RPS)).experiment
    true = Calibration.from_result(truth)
    fig = {}
    for name, e in (("whole", exp), ("cut", cut)):
        rests = record_rests(e)
        fig[name] = held_out_figures(e, Fold(index=0, spans=((0, e.n_samples),), rests=(rests,)), true)
    assert fig["whole"].transitions_max_deg > 5.0
    assert fig["cut"].transitions_max_deg < 0.2


def test_flat_tops_find_a_saturated_gyro_the_record_was_not_cut_for(clipped):
    """The clipped record kept whole: its gyro sits at the range in a run the verdict notes (with the option that
    cuts it); cut, or never clipped, nothing is seen."""
    from graph_calib.evaluation.crossval import record_rests

    exp, _ = clipped
    tops = flat_tops(exp, rests=record_rests(exp))
    assert tops["episodes"] == 1 and list(tops["axes"]) == ["z"]
    assert abs(tops["axes"]["z"][0]) == pytest.approx(RANGE_RPS)
    cut = cut_at_saturation(exp, saturated_rates(exp, gyro_range_rps=RANGE_RPS)).experiment
    assert flat_tops(cut, rests=record_rests(cut)) is None
    run = calibrate(exp, options=CONSUMER, solvers=("factor-graph",))
    assert any("sit at their largest output" in n and "--gyro-range-dps" in n for n in run.verdict.notes)
    se = simulate("consumer-ferraris", rng=np.random.default_rng(2)).plans[0].make()
    assert flat_tops(se.experiment, rests=record_rests(se.experiment)) is None


def test_the_measured_sessions_show_flat_tops_only_where_the_mpu6050_saturates(real_data):
    """The MPU-6050 session kept whole: its 18 samples at the int16 limits; cut, none. The Xsens session's gyro creeps
    at about 381 deg/s in its last motion, after its last rest: no rotation factor ties that to a later rest."""
    from graph_calib.evaluation.crossval import record_rests
    from graph_calib.importers import import_mpu6050, import_xsens

    mpu = real_data / "mpu6050_uncuyo" / "example_data_calibration.csv"
    whole = import_mpu6050(mpu, cut_saturated=False)
    tops = flat_tops(whole, rests=record_rests(whole))
    assert tops["samples"] == 18 and tops["episodes"] == 3 and sorted(tops["axes"]) == ["x", "z"]
    cut = import_mpu6050(mpu)
    assert flat_tops(cut, rests=record_rests(cut)) is None
    xs = import_xsens(real_data / "imu_tk_xsens" / "xsens_acc.mat", real_data / "imu_tk_xsens" / "xsens_gyro.mat")
    assert flat_tops(xs, rests=record_rests(xs)) is None


def test_an_episode_at_the_record_s_start_is_not_cut(clipped):
    """Saturated samples before the first rest: the piece before a cut would have no rest to align it, so the record
    is kept whole there, and its description says so."""
    exp, _ = clipped
    sat = np.zeros(exp.n_samples, dtype=bool)
    sat[:3] = True
    cuts = cut_at_saturation(exp, sat)
    assert cuts.episodes.tolist() == [[0, 3]] and cuts.cut.tolist() == [False]
    assert cuts.experiment.segment is None and "those starting at 0 are kept" in cuts.experiment.description
