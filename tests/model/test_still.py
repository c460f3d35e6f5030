"""The still factors of a rest: Jacobians against finite differences, the fusion with the rotation factors, and
when a model has them."""

from dataclasses import replace

import numpy as np
import pytest

from graph_calib.model import CalibrationModel, ModelOptions
from graph_calib.model.calibration_model import STILL_FRACTION
from graph_calib.model.residual_list import FACTOR_KINDS, residual_list
from graph_calib.model.still_fusion import fuse_still
from graph_calib.navigation.rotations import log_so3

from _synthetic import assert_pair_jacobians_match_fd, perturbed_point, wobbly_experiment

EPS = 1e-6


def _static_mask(exp):
    """Every other 2.2 s of the record taken as a rest (each holds whole keyframes of 0.5 s inside its edges)."""
    return np.floor(exp.t / 2.2) % 2 == 0


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(4)
    exp = wobbly_experiment(rng=rng)
    model = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, still_at_rest=True),
                             static_mask=_static_mask(exp))
    return (model, *perturbed_point(model, rng=rng))


def test_still_factor_jacobians_in_both_attitudes_match_fd(problem):
    model, x, preint, R = problem
    res = model.still_factors(R, preint, x)
    assert res.key.size >= 3 and not np.any(res.H_x)
    for j, k in enumerate(res.key[:4]):
        assert_pair_jacobians_match_fd(lambda R_: model.still_factors(R_, preint, x), R, index=j, key=k,
                                       H_R=res.H_R[j], H_R_next=res.H_R_next[j], eps=EPS, atol=1e-8)


def test_still_factor_sigma_is_a_tenth_of_the_gyro_noise_over_the_keyframe(problem):
    model, x, preint, R = problem
    res = model.still_factors(R, preint, x)
    T = model.record.T_key[res.key]
    np.testing.assert_allclose(res.sigma[:, 0], STILL_FRACTION * model.noise.gyro * np.sqrt(T), rtol=1e-12)
    doubled = CalibrationModel.from_record(model.record, options=replace(model.options, variance_factors={"still": 4.0}))
    np.testing.assert_allclose(doubled.still_factors(R, preint, x).sigma, 2.0 * res.sigma, rtol=1e-12)


def test_fusion_is_orthogonal_keeps_the_cost_and_frees_the_measurement_of_the_next_attitude(problem):
    model, x, preint, R = problem
    rot, still = model.rotation_factors(R, preint, x), model.still_factors(R, preint, x)
    frot, fstill = fuse_still(rot, still)
    before = np.sum((rot.r / rot.sigma) ** 2) + np.sum((still.r / still.sigma) ** 2)
    after = np.sum((frot.r / frot.sigma) ** 2) + np.sum((fstill.r / fstill.sigma) ** 2)
    np.testing.assert_allclose(after, before, rtol=1e-12)
    assert fstill.H_R_next is None
    idx = np.searchsorted(rot.key, still.key)
    other = np.setdiff1d(np.arange(rot.key.size), idx)
    np.testing.assert_array_equal(frot.r[other], rot.r[other])          # the moving keyframes' untouched
    for j, i in enumerate(idx):
        # the map of the six whitened rows: [process; measurement] = Q^T [rotation; still]
        w1, w2 = 1.0 / rot.sigma[i], 1.0 / still.sigma[j]
        A_N, B_N = rot.H_R_next[i] * w1[:, None], still.H_R_next[j] * w2[:, None]
        A_R, B_R = rot.H_R[i] * w1[:, None], still.H_R[j] * w2[:, None]
        stacked = np.vstack([np.column_stack([rot.r[i] * w1, A_R, A_N]), np.column_stack([still.r[j] * w2, B_R, B_N])])
        target = np.vstack([np.column_stack([frot.r[i], frot.H_R[i], frot.H_R_next[i]]),
                            np.column_stack([fstill.r[j], fstill.H_R[j], np.zeros((3, 3))])])
        Q_T, *_ = np.linalg.lstsq(stacked.T, target.T, rcond=None)
        Q_T = Q_T.T
        np.testing.assert_allclose(Q_T @ Q_T.T, np.eye(6), atol=1e-9)   # orthogonal: whitened rows stay unit, independent
        mapped = np.vstack([np.column_stack([frot.r[i], frot.H_R[i], frot.H_R_next[i]]),
                            np.column_stack([fstill.r[j], fstill.H_R[j], np.zeros((3, 3))])])
        np.testing.assert_allclose(Q_T @ stacked, mapped, rtol=0, atol=1e-12 * np.abs(stacked).max())


def test_the_still_measurement_is_the_rests_gyro_integral_over_its_noise(problem):
    """To first order the fused still row is the gyros' turn over the keyframe less the Earth's turn seen in the
    body, ``Log(dR) - R_k^T omega_ie_n T``, over the gyro's noise over the keyframe (with the 1 % of the still
    factor's own variance)."""
    model, x, preint, R = problem
    rot, still = model.rotation_factors(R, preint, x), model.still_factors(R, preint, x)
    _, fstill = fuse_still(rot, still)
    k = still.key
    T = model.record.T_key[k]
    turn = log_so3(preint.corrected(x).dR[k]) - np.einsum("kji,j->ki", R[k], model.omega_ie_n) * T[:, None]
    expected = turn / (model.noise.gyro * np.sqrt(T) * np.sqrt(1.0 + STILL_FRACTION ** 2))[:, None]
    np.testing.assert_allclose(fstill.r, expected, atol=0.05 * np.abs(expected).max())


def test_residual_list_gives_the_still_kind_as_a_measurement(problem):
    model, x, preint, R = problem
    factors = residual_list(model, R, preint, x)
    assert "still" in [k.name for k in FACTOR_KINDS] and factors["still"].H_R_next is None
    assert factors["still"].key.size == model.still_keys.size > 0


def test_which_records_have_still_factors():
    rng = np.random.default_rng(5)
    exp = wobbly_experiment(rng=rng)
    mask = _static_mask(exp)
    default = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5), static_mask=mask)
    assert default.still_keys.size == 0                                             # off by default
    on = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, still_at_rest=True), static_mask=mask)
    assert on.still_keys.size > 0 and np.all(on.record.static_key[on.still_keys])
    assert np.all(np.isin(on.still_keys, on.record.rotation_keys))
    unknown = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, still_at_rest=True))
    assert unknown.still_keys.size == 0                                             # no rests known: none


def test_a_rests_edge_keyframes_have_no_still_factor_a_lone_one_has():
    """The static detector's window smears a rest's edges (an edge keyframe may hold the start of a turn): the first
    and last keyframes of a rest of several keyframes get no still factor; a rest of one keyframe (a short rest on its
    own grid) keeps its own."""
    rng = np.random.default_rng(6)
    exp = wobbly_experiment(rng=rng)
    model = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, still_at_rest=True),
                             static_mask=_static_mask(exp))
    s = model.record.static_key
    k = model.still_keys
    assert k.size > 0
    for j in k:
        lone = (j == 0 or not s[j - 1]) and (j + 1 == s.size or not s[j + 1])
        assert lone or (s[j - 1] and s[j + 1]), j
    starts = np.flatnonzero(s & ~np.concatenate([[False], s[:-1]]))
    long_starts = [j for j in starts if j + 1 < s.size and s[j + 1]]
    assert long_starts and not np.isin(long_starts, k).any()
    lone = np.zeros_like(s)
    lone[5] = True
    mask = np.zeros(exp.t.size, dtype=bool)
    mask[model.record.k0[5]:model.record.k0[6]] = True
    single = CalibrationModel(exp, options=ModelOptions(keyframe_s=0.5, still_at_rest=True), static_mask=mask)
    assert list(single.still_keys) == [5]


def test_a_rest_rows_variance_is_the_gyros_but_for_the_still_factors_share(problem):
    """A fused still row's variance is the rotation factor's (the gyro's noise over the keyframe) and the still
    factor's; the latter's share is 0.1^2 / (1 + 0.1^2) at unit factors and follows both kinds' factors."""
    model, *_ = problem
    np.testing.assert_allclose(model.still_share(), STILL_FRACTION ** 2 / (1.0 + STILL_FRACTION ** 2), rtol=1e-12)
    scaled = CalibrationModel.from_record(model.record, options=replace(model.options,
                                                                        variance_factors={"rotation": 99.0}))
    np.testing.assert_allclose(scaled.still_share(), STILL_FRACTION ** 2 / (99.0 + STILL_FRACTION ** 2), rtol=1e-12)
