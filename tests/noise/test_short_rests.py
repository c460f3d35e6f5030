"""Short rests (a hand holding a face 0.5-1.5 s) as static intervals and static keyframes (issue 22)."""

import numpy as np

from graph_calib.calibrate import build_problem
from graph_calib.model import ModelOptions
from graph_calib.model.record import PreparedRecord
from graph_calib.options import CalibrationOptions
from graph_calib.navigation.static_detection import detect_static
from graph_calib.noise.rests import SHORT_REST_WINDOWS, segment_static, segment_thresholds, short_window_s
from graph_calib.records.problem import sway_from_static
from graph_calib.simulation.scenarios import SHORT_REST_FERRARIS, simulate

from _synthetic import wobbly_experiment


def _short_session(seed):
    se = simulate("consumer-ferraris", rng=np.random.default_rng(seed), **SHORT_REST_FERRARIS).plans[0].make()
    holds = np.array([(r[0], r[0] + r[1]) for r in se.signals.motion._rows if not np.any(r[3])])
    return se.experiment, holds


def test_the_short_window_follows_from_the_scatter_statistics():
    assert 24 <= short_window_s(100.0) * 100.0 <= 26            # 25 samples at 100 Hz
    assert short_window_s(1000.0) == 0.2                          # never shorter than the floor
    assert SHORT_REST_WINDOWS * short_window_s(100.0) <= 0.51     # rests of 0.5 s are kept


def test_every_short_rest_of_a_hand_held_ferraris_session_is_found():
    exp, holds = _short_session(1)
    assert holds.shape[0] == 12 and np.all((holds[:, 1] - holds[:, 0]) / exp.rate_hz < 1.6)
    [(a, b, piece, th)] = segment_thresholds(exp)
    # detect_static's defaults (1 s window, 2 s minimum) see at most one of them
    assert detect_static(piece, threshold=th).shape[0] <= 1
    found = segment_static(piece, threshold=th)
    assert found.shape[0] == holds.shape[0]
    # each within its true rest, give or take the slow ends of the hand's turns (0.15 s)
    slack = int(0.15 * exp.rate_hz)
    assert np.all(found[:, 0] >= holds[:, 0] - slack) and np.all(found[:, 1] <= holds[:, 1] + slack)
    assert np.all(found[:, 1] - found[:, 0] >= 0.4 * exp.rate_hz)


def test_a_rest_without_a_whole_keyframe_is_one_and_the_others_keep_the_grid():
    exp = wobbly_experiment(rng=np.random.default_rng(0), n=1000, with_table=False)
    mask = np.zeros(exp.n_samples, dtype=bool)
    mask[130:190] = True                 # 0.6 s: a short rest, its ends cut
    mask[400:700] = True                 # 3 s: detect_static's, the grid
    rec = PreparedRecord(exp, keyframe_s=1.0, static_mask=mask, short_rests=[[130, 190]])
    assert 130 in rec.k0 and 190 in rec.k0
    spans = [(int(rec.k0[k]), int(rec.k0[k + 1])) for k in np.flatnonzero(rec.static_key)]
    assert spans[0] == (130, 190)
    # the grid restarts at the cut: two whole keyframes inside the long rest
    assert spans[1:] == [(490, 590), (590, 690)]
    assert np.isclose(rec.T_key[np.flatnonzero(rec.static_key)[0]], 0.6)
    # a rest that holds a whole keyframe of the grid leaves it as it is
    mask[130:190] = False
    mask[100:290] = True
    plain = PreparedRecord(exp, keyframe_s=1.0, static_mask=mask, short_rests=[[100, 290]])
    assert np.array_equal(plain.k0, np.append(np.arange(0, 1000, 100), 1000))
    assert [int(plain.k0[k]) for k in np.flatnonzero(plain.static_key)] == [100, 400, 500, 600]
    # detect_static's rests never move it (the measured sessions keep their keyframes)
    mask[:] = False
    mask[130:190] = True
    assert np.array_equal(PreparedRecord(exp, keyframe_s=1.0, static_mask=mask).k0, plain.k0)


def test_every_short_rest_of_the_session_is_a_static_keyframe():
    exp, holds = _short_session(2)
    problem = build_problem(exp, options=CalibrationOptions(model=ModelOptions(grade="consumer")))
    rec = problem.model.record
    # every short rest a static keyframe at least (detect_static's long one, if any, holds one of the grid)
    assert int(rec.static_key.sum()) >= holds.shape[0] - 1


def test_the_sway_is_seen_on_short_rests():
    rng = np.random.default_rng(3)
    exp = wobbly_experiment(rng=rng, n=3000, with_table=False)
    rests = np.array([[100 + 250 * i, 180 + 250 * i] for i in range(10)])     # ten rests of 0.8 s
    t = exp.t[:, None]
    still = np.tile([0.0, 0.0, 9.81], (exp.n_samples, 1)) + 0.02 * rng.standard_normal((exp.n_samples, 3))
    sway = still + 0.1 * np.sin(2 * np.pi * 1.3 * t + rng.uniform(0, 6, 3))
    noise = 0.02 / np.sqrt(exp.rate_hz)          # the white density of the 0.02 m/s^2 per sample
    for f, expect in ((still, 0.0), (sway, None)):
        e = exp.__class__(**{**exp.__dict__, "dv": f * exp.dt[:, None]})
        s = sway_from_static(e, rests, keyframe_s=1.0, accel_noise=noise)
        if expect is not None:
            assert s == expect
        else:
            assert 0.02 < s < 0.2
