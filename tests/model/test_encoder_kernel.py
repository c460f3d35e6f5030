"""The compiled encoder rows (graph_calib.model.encoder_kernel) against the same formulas written with numpy stacks."""

import numpy as np
import pytest

from graph_calib.model import CalibrationModel, ModelOptions
from graph_calib.model import factors
from graph_calib.model.encoder_noise import NoiseFrame
from graph_calib.navigation.rotations import exp_so3, log_so3, right_jacobian, right_jacobian_inv
from graph_calib.sensors.effects import FURTHER_EFFECTS

from _synthetic import wobbly_experiment


def _reference_rows(record, R, preint, x, layout, frame):
    """``(r, H_R, H_x)`` of every reading, each step a numpy stack (the module docstring's formulas)."""
    M, P = record.reading_sample.size, layout.size
    dx = np.asarray(x) - preint.x_lin
    gc = preint.gyro_cols
    J_w = preint.reading_rate_jacobian()
    readR = preint.reading_dR @ exp_so3(preint.reading_J @ dx[gc])
    w_c = preint.reading_w + J_w @ dx[gc]
    dt = record.reading_dt
    phi = w_c * dt[:, None] + record.reading_phi_shape
    Ew = exp_so3(phi)
    Bp = readR @ Ew
    C_pred = record.reading_E @ R[record.reading_key] @ Bp
    mount = layout.get(x, "mount", np.zeros(3))
    lag = layout.get(x, "time_lag.table", np.zeros(1))[0]
    Kd = layout.get(x, "damping.stiffness", np.zeros(9)).reshape(3, 3)
    w_nb = w_c + record.reading_w_nb_offset
    a_lag = w_nb * lag - (0.5 * lag * lag) * record.reading_alpha
    a_damp = record.reading_f @ Kd.T
    Ed = exp_so3(a_damp) if np.any(Kd) else np.broadcast_to(np.eye(3), (M, 3, 3))
    B = exp_so3(a_lag) @ Ed if lag != 0.0 else Ed
    C_meas = record.reading_C_nb_nominal @ (exp_so3(mount) @ B)
    r = log_so3(np.swapaxes(C_meas, 1, 2) @ C_pred)
    Jr_inv, Jl_inv = right_jacobian_inv(r), right_jacobian_inv(-r)
    H_R = Jr_inv @ np.swapaxes(Bp, 1, 2)
    H_x = np.zeros((M, 3, P))
    G_w = np.swapaxes(Ew, 1, 2) @ preint.reading_J + (right_jacobian(phi) * dt[:, None, None]) @ J_w
    H_x[:, :, gc] = Jr_inv @ G_w
    if "mount" in layout:
        H_x[:, :, layout.slice("mount")] = -Jl_inv @ np.swapaxes(B, 1, 2) @ right_jacobian(mount)
    if "time_lag.table" in layout:
        G_lag = -Jl_inv @ np.swapaxes(Ed, 1, 2) @ right_jacobian(a_lag)
        H_x[:, :, layout.slice("time_lag.table")] = G_lag @ (w_nb - lag * record.reading_alpha)[..., None]
        H_x[:, :, gc] += G_lag @ (lag * J_w)
    if "damping.stiffness" in layout:
        G = -Jl_inv @ right_jacobian(a_damp)
        H_x[:, :, layout.slice("damping.stiffness")] = np.einsum("mab,mj->mabj", G, record.reading_f).reshape(M, 3, 9)
    Ut = np.where(frame.rotated[:, None, None], np.swapaxes(frame.U, 1, 2), np.eye(3))
    return np.einsum("mij,mj->mi", Ut, r), Ut @ H_R, Ut @ H_x


@pytest.fixture(scope="module")
def grown():
    """A wobbly record with every further effect, the calibration away from its preintegration point, a time lag,
    a damping stiffness and a mount, and every other reading turned into random noise axes."""
    rng = np.random.default_rng(5)
    model = CalibrationModel(wobbly_experiment(rng=rng), options=ModelOptions(keyframe_s=0.5,
                                                                             extra_effects=FURTHER_EFFECTS))
    lay = model.layout
    x_lin = rng.normal(size=lay.size) * 1e-3
    preint = model.preintegrate(x_lin)
    x = x_lin + rng.normal(size=lay.size) * 1e-4
    x[lay.slice("time_lag.table")] = 0.01
    x[lay.slice("damping.stiffness")] = rng.normal(size=9) * 1e-4
    x[lay.slice("mount")] = rng.normal(size=3) * 1e-2
    R = model.propagate(np.eye(3), preint, x) @ exp_so3(rng.normal(size=(model.n_keyframes + 1, 3)) * 1e-2)
    M = model.record.reading_sample.size
    frame = NoiseFrame(U=exp_so3(rng.normal(size=(M, 3))), var=np.ones((M, 3)), rotated=np.arange(M) % 2 == 0,
                       floored=np.zeros((M, 3), bool), source=np.ones(M, np.int8))
    return model, preint, x, R, frame


@pytest.mark.parametrize("case", ["grown", "no lag, no damping, at the preintegration point"])
def test_compiled_rows_equal_the_numpy_formulas(grown, case):
    model, preint, x, R, frame = grown
    lay = model.layout
    if case != "grown":
        x = preint.x_lin.copy()
        x[lay.slice("time_lag.table")] = 0.0
        x[lay.slice("damping.stiffness")] = 0.0
        preint = model.preintegrate(x)
    M, P = model.record.reading_sample.size, lay.size
    r, H_R, H_x = np.empty((M, 3)), np.empty((M, 3, 3)), np.zeros((M, 3, P))
    factors._encoder_rows(model.record, R, preint, x, lay, frame, r, H_R, H_x)
    r0, H_R0, H_x0 = _reference_rows(model.record, R, preint, x, lay, frame)
    assert np.abs(r0).max() > 1e-3 and np.abs(H_x0[:, :, lay.slice("damping.stiffness")]).max() > 0
    np.testing.assert_allclose(r, r0, rtol=0, atol=1e-13 * np.abs(r0).max())
    np.testing.assert_allclose(H_R, H_R0, rtol=0, atol=1e-13)
    for c in range(P):
        np.testing.assert_allclose(H_x[:, :, c], H_x0[:, :, c], rtol=0, atol=1e-12 * (1 + np.abs(H_x0[:, :, c]).max()),
                                   err_msg=lay.element_names()[c])


def test_the_model_factor_is_the_compiled_rows(grown):
    """``encoder_factors`` is the kernel's rows of every reading, turned where the record's own noise frame says."""
    model, preint, x, R, _ = grown
    frame = model.record.encoder_noise_frame(model.noise.encoder)
    res = model.encoder_factors(R, preint, x)
    r0, H_R0, H_x0 = _reference_rows(model.record, R, preint, x, model.layout, frame)
    np.testing.assert_allclose(res.r, r0, rtol=0, atol=1e-13 * np.abs(r0).max())
    np.testing.assert_allclose(res.H_R, H_R0, rtol=0, atol=1e-13)
    np.testing.assert_allclose(res.H_x, H_x0, rtol=0, atol=1e-12 * (1 + np.abs(H_x0).max()))
