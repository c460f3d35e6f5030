r"""The factors of the shared model: one place for every equation every solver uses.

The record is cut into keyframe intervals (about 0.1-1 s).  For interval ``k``,
``R_k = C_nb`` at its start, and with the gyro and accelerometer samples
corrected by the calibration ``x`` (:mod:`graph_calib.sensors.sensor_model`):

Rotation (process) model
    ``R_{k+1} = E(T_k) @ R_k @ dR_k(x)``, with ``dR_k`` the preintegrated
    rotation of the corrected increments (two-sample coning correction) and
    ``E(T) = Exp(-omega_ie_n * T)`` the turn of the level frame with the Earth.
    Residual ``Log((E R_k dR_k)^T R_{k+1})``, covariance ``q_g^2 T_k I``
    (``q_g`` the gyro angle random walk).  A gyro whose integrated angle carries a white error ``Q``
    at each sample end (a ring-laser gyro's quantization, ``Noise.gyro_quantization``) adds
    ``Q_{k+1} - Q_k`` to this residual, but the keyframe attitudes absorb it (they are the gyros'
    indicated attitudes): the rotation factors keep ``q_g`` alone, and ``Q`` reaches the factors that
    read the attitude between keyframes: ``Q^2 ((1 - a)^2 + a^2)`` on an encoder reading a fraction
    ``a`` into its sample interval, ``g^2 Q^2 / n`` on a gravity factor's horizontal axes (n samples).

Gravity measurement
    The specific force integrated in the level frame over the interval, each
    sample rotated with its own attitude,
    ``dv_n = sum_j C_nb(t_{j-1}) u_j``,
    ``u = dv + 1/2 dth x dv + 1/6 dth x (dth x dv) + h^2/12 (dth x fdot - alpha x dv)``
    (exact to third order in the sample interval ``h`` when the rate and the
    specific force vary linearly over the sample; the angular acceleration
    ``alpha`` and ``fdot = df_b/dt`` are taken from the raw data),
    equals ``g_up * T_k`` plus the change of the velocity of the accelerometer
    point, ``C_nb (omega_nb_b x l)`` (the rotation centre is fixed), and the
    Coriolis integral ``2 omega_ie_n x`` the change of its position ``C_nb l``:
    with ``v = C_nb (omega_ib_b x l) + omega_ie_n x (C_nb l)`` (which is both),
    ``r = (dv_n - [v(t_{k+1}) - v(t_k)]) / T_k - [0, 0, g]``.  With
    ``C_nb(t) = E(t - t_k) R_k dR(t)``, ``dv_n = R_k S - [omega_ie_n x] R_k S1``
    where ``S = sum dR_{j-1} u_j`` and ``S1 = sum (t_{j-1} + h_j/2 - t_k) dR_{j-1} u_j``
    are preintegrated once per calibration.  Covariance
    ``q_a^2 / T_k`` per axis plus ``g^2 q_g^2 T_k / 3`` on the horizontal axes
    (attitude noise inside the interval, the rotation factor's noise too: made independent in the residual list,
    :mod:`graph_calib.model.gravity_gyro_noise`), plus ``2/3 |l|^2 (s_k^2 + s_{k+1}^2) / T_k^2`` on every axis,
    ``s`` the boundary rates' scatter (:func:`graph_calib.model.local_rates.local_rates`) and ``l`` the lever
    arm at the preintegration's linearisation point.

Encoder measurement
    A valid table reading at ``t_m`` (sample ``j``, ``dt_m = t_m - t_j``; the
    sample interval of length ``h`` holding ``t_m`` has the calibrated mean rate
    ``w(x)`` and the raw slope ``alpha``, the rate taken linear inside it):
    ``C_meas = C_nf(t_m) C_fb Exp(mount) Exp(a_lag) Exp(K f_m)`` against
    ``C_pred = E(t_m - t_k) R_k dR_{k,j} Exp(phi)``, residual
    ``Log(C_meas^T C_pred)``, with the turn from the sample end to the reading
    ``phi = w dt_m + alpha dt_m (dt_m - h) / 2`` and the turn over the lag before
    it ``a_lag = w_nb lag - alpha lag^2 / 2``, ``w_nb = w + alpha (dt_m - h/2) -
    (C_nf C_fb)^T omega_ie_n`` (the rate against the level frame at ``t_m``);
    ``f_m`` is the raw specific force of that interval and ``K``
    ``damping.stiffness`` when modelled.  Covariance ``Sigma_enc + q_g^2 (t_m - t_k) I``, where
    ``Sigma_enc`` is a static dwell's scatter, or the declared ``sigma_enc^2`` about the table's axes
    when they are known, or ``sigma_enc^2 I`` (readings in motion), principal variances floored
    (:mod:`graph_calib.model.encoder_noise`); residual and Jacobians are turned into its principal
    axes, ``U^T r``, so that each component has its own sigma.  The gyro term is shared: the readings of one
    interval and its rotation factor carry the same gyro noise up to the earlier time, which
    :mod:`graph_calib.model.shared_gyro_noise` makes independent in the residual list (each function here
    gives its kind on its own).

Still measurement (a rest; records without a table by default, ``ModelOptions.still_at_rest``)
    Over a static keyframe the unit does not turn in the level frame: ``R_{k+1} = R_k``, residual
    ``Log(R_k^T R_{k+1})``, sigma a tenth of the gyro's noise over the keyframe (a unit at rest turns by less
    than its gyros can tell; the kind's variance factor scales it).  With the keyframe's rotation factor it
    makes the rest's gyro integral a measurement of the gyro biases against the Earth's turn (a zero-rate
    update); :mod:`graph_calib.model.still_fusion` gives the pair to the solvers as one process factor and one
    measurement of ``R_k``.

Jacobians are with respect to the right perturbation of ``R_k``
(``R_k Exp(delta)``) and the calibration vector; the preintegration carries its
first-order Jacobian in ``x``, so a small change ``dx`` from the linearisation
point is applied as ``dR Exp(J dx)``, ``S + J_S dx``; the caller re-preintegrates
when ``dx`` grows (:meth:`graph_calib.model.preintegration.Preintegrated.needs_repreintegration`).

Priors are residuals like the others (:class:`PriorResidual`): the prior of the first keyframe
attitude (the alignment) and of the calibration vector (the grade's priors).

Segments (``/imu/segment``: a record cut together from pieces)
    Keyframes never span a segment boundary; the first keyframe of each segment has an attitude
    prior of its own (that segment's alignment) and no rotation factor ties it to the previous
    segment's last keyframe, whose gravity factor still counts (its end attitude ``E R_k dR_k`` is
    that keyframe's own).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from graph_calib.model.encoder_kernel import encoder_rows
from graph_calib.model.encoder_noise import FLOORED
from graph_calib.navigation.rotations import exp_so3, log_so3, right_jacobian, right_jacobian_inv, skew


@dataclass(frozen=True)
class Noise:
    """White-noise levels of the factors.

    Attributes
    ----------
    gyro : float
        Angle random walk, rad/sqrt(s).
    accel : float
        Velocity random walk, m/s/sqrt(s).
    encoder : float
        Declared table reading noise, rad (one sigma per axis): the readings' noise where no static
        dwell shows it, and the scale of the floor where one does (:mod:`graph_calib.model.encoder_noise`).
    variance_factors : dict
        ``{kind: factor}`` multiplying each kind's covariance (variance components; 1 where absent).  The
        table readings' gyro term is the gyro's noise and takes the ``rotation`` factor; ``encoder`` multiplies
        the readings' own noise but the floor of their floored components, which takes
        :data:`graph_calib.model.encoder_noise.FLOORED` instead.
    gyro_quantization : float
        White error of the gyros' integrated angle at each sample end, rad (a ring-laser gyro's
        quantization, IEEE ``Q``; 0: none).  The keyframe attitudes are the gyros' *indicated* ones,
        which carry it, so the rotation factors see only ``gyro`` (the angle random walk) and the
        measurements that read the attitude between keyframes see ``Q`` (module doc).
    """

    gyro: float
    accel: float
    encoder: float
    variance_factors: dict = field(default_factory=dict)
    gyro_quantization: float = 0.0

    def scaled(self, kind, res):
        """``res`` (:class:`Residuals` of ``kind``) with its covariance times the kind's variance factor."""
        v = float(self.variance_factors.get(kind, 1.0))
        if v == 1.0:
            return res
        return replace(res, sigma=res.sigma * (v if res.sigma.ndim == 3 else np.sqrt(v)))


@dataclass(frozen=True)
class Residuals:
    """One kind of factor, stacked: residual, Jacobians and one-sigma noise.

    Attributes
    ----------
    r : (F, 3)
    key : (F,) int       keyframe whose attitude the factor touches (the first one)
    H_R : (F, 3, 3)      d r / d delta of that keyframe
    H_R_next : (F, 3, 3) or None   d r / d delta of keyframe key+1 (rotation factors)
    H_x : (F, 3, P)      d r / d x
    sigma : (F, 3)       one sigma per component (a full noise covariance is turned into its principal axes
                         by the factor itself, as the encoder factor does)
    """

    r: np.ndarray
    key: np.ndarray
    H_R: np.ndarray
    H_R_next: np.ndarray | None
    H_x: np.ndarray
    sigma: np.ndarray

    def whitened(self):
        """Residuals divided by their sigmas (no robust weight); the normal equations' rows:
        :func:`graph_calib.model.residual_list.whiten`."""
        return self.r / self.sigma


def rotation_factors(record, R, preint, x, *, noise):
    """Residuals between consecutive keyframe attitudes ``R`` (K+1, 3, 3).

    One factor per keyframe ``k`` of ``record.rotation_keys``: every keyframe but the last of each
    segment (``/imu/segment``), since attitude is never continuous across a segment boundary (one
    segment: all ``K``; ``key`` tells which).

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
    R : ndarray, shape (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.
    preint : graph_calib.model.preintegration.Preintegrated
    x : ndarray, shape (P,)
    noise : Noise

    Returns
    -------
    Residuals
    """
    k = record.rotation_keys
    dR = preint.corrected(x).dR[k]
    E = record.earth_turn(record.T_key[k])
    A = E @ R[k] @ dR
    r = log_so3(np.swapaxes(A, 1, 2) @ R[k + 1])
    Jr_inv = right_jacobian_inv(r)
    Jl_inv = right_jacobian_inv(-r)
    H_next = Jr_inv
    H_prev = -Jl_inv @ np.swapaxes(dR, 1, 2)
    H_x = -Jl_inv @ preint.J_dR[k]
    sigma = noise.gyro * np.sqrt(record.T_key[k])[:, None] * np.ones(3)
    return Residuals(r=r, key=k.copy(), H_R=H_prev, H_R_next=H_next, H_x=H_x, sigma=sigma)

def still_factors(record, R, preint, x, *, keys, sigma):
    """A body at rest does not turn in the level frame: ``R_{k+1} = R_k`` over a static keyframe.

    Over keyframe ``k`` of a rest the unit sits on a surface (or in a hand) fixed to the Earth, as the level
    frame is, so its attitude at the keyframe's end is the one at its start.  Residual ``Log(R_k^T R_{k+1})``,
    rad, with one sigma ``sigma`` per axis: how far a unit at rest may turn over the keyframe (a hand's tremor;
    the keyframe attitudes are the gyros' indicated ones, so a ring-laser gyro's quantization at the two ends is
    in it too, :meth:`graph_calib.model.CalibrationModel.still_factors`).  Beside the keyframe's rotation factor
    it says that the gyros' integral over the rest is the Earth's turn seen in the body: what a zero-rate update
    does in a filter, and what a Ferraris calibration's rests give its gyro biases.

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
        Unused (the factor reads the attitudes alone); in the signature every factor has.
    R : ndarray, shape (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.
    preint : graph_calib.model.preintegration.Preintegrated
        Unused, as ``record``.
    x : ndarray, shape (P,)
        The calibration (its size only: the factor does not depend on it).
    keys : ndarray of int, shape (F,)
        The static keyframes with a rotation factor (``record.rotation_keys``).
    sigma : ndarray, shape (F,)
        One sigma per factor, rad.

    Returns
    -------
    Residuals
        ``H_x`` zero; ``H_R_next`` the Jacobian in ``R_{k+1}``.
    """
    k = np.asarray(keys, dtype=np.int64)
    r = log_so3(np.swapaxes(R[k], 1, 2) @ R[k + 1])
    H_next = right_jacobian_inv(r)
    H_prev = -right_jacobian_inv(-r)
    H_x = np.zeros((k.size, 3, np.asarray(x).size))
    return Residuals(r=r, key=k.copy(), H_R=H_prev, H_R_next=H_next, H_x=H_x,
                     sigma=np.asarray(sigma, dtype=float)[:, None] * np.ones(3))


def gravity_factors(record, R, preint, x, *, layout, noise, moving_sigma=None, sway_sigma=None):
    """Gravity (reaction-force) mismatch of every keyframe, m/s^2; ``R`` (K+1 or K, 3, 3).

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
    R : ndarray, shape (K+1, 3, 3) or (K, 3, 3)
    preint : graph_calib.model.preintegration.Preintegrated
    x : ndarray, shape (P,)
    layout : graph_calib.sensors.params.Layout
    noise : Noise
    moving_sigma : float, optional
        Sigma (m/s^2) of the keyframes that are not static (a bench that may translate).
    sway_sigma : float, optional
        Sigma (m/s^2) of the bench's own acceleration over a keyframe (a hand's sway), added in
        quadrature on every axis of every keyframe.

    Returns
    -------
    Residuals
    """
    K = record.n_keyframes
    Rk = R[:K]
    c = preint.corrected(x)
    dR, S, S1, w_b = c.dR, c.S, c.S1, c.w_b
    W = skew(record.omega_ie_n)
    T = record.T_key
    l = layout.get(x, "lever_arm", np.zeros(3))
    E = record.earth_turn(T)
    C1 = E @ Rk @ dR                                         # attitude at the keyframe end
    dv_n = np.einsum("kij,kj->ki", Rk, S) - np.einsum("ij,kjl,kl->ki", W, Rk, S1)
    a0 = np.cross(w_b[:-1], l)                               # omega x l at the start
    a1 = np.cross(w_b[1:], l)
    # v = C (omega_ib x l) + omega_ie x (C l): the point's velocity in the Earth-fixed level frame,
    # C (omega_nb x l), plus 2 omega_ie x (C l) whose change is the Coriolis integral
    v0 = np.einsum("kij,kj->ki", Rk, a0) + np.cross(record.omega_ie_n, np.einsum("kij,j->ki", Rk, l))
    v1 = np.einsum("kij,kj->ki", C1, a1) + np.cross(record.omega_ie_n, np.einsum("kij,j->ki", C1, l))
    g_up = np.array([0.0, 0.0, record.gravity])
    r = (dv_n - (v1 - v0)) / T[:, None] - g_up
    # Jacobian in the right perturbation of R_k
    H_R = -Rk @ skew(S) + W @ Rk @ skew(S1)
    H_R += -Rk @ skew(a0) - W @ Rk @ skew(l)                 # -(-dv0)
    dRT = np.swapaxes(dR, 1, 2)
    H_R -= (-C1 @ skew(a1) - W @ C1 @ skew(l)) @ dRT
    # Jacobian in x
    H_x = Rk @ preint.J_S - W @ Rk @ preint.J_S1
    # v0 = Rk (w0 x l) + ...: d/dw0 = -Rk [l x]; d/dl = Rk [w0 x] + W Rk
    H_x -= Rk @ skew(l) @ preint.J_w_b[:-1]
    H_x -= -C1 @ skew(l) @ preint.J_w_b[1:]
    # C1 depends on x through dR: d(C1 a) = -C1 [a x] J
    H_x -= (-C1 @ skew(a1) - W @ C1 @ skew(l)) @ preint.J_dR
    if "lever_arm" in layout:
        s = layout.slice("lever_arm")
        H_x[:, :, s] += Rk @ skew(w_b[:-1]) + W @ Rk
        H_x[:, :, s] -= C1 @ skew(w_b[1:]) + W @ C1
    r_scale = 1.0 / T[:, None, None]
    H_R = H_R * r_scale
    H_x = H_x * r_scale
    var = np.empty((K, 3))
    var[:] = (noise.accel**2 / T)[:, None]
    var[:, :2] += (record.gravity * noise.gyro) ** 2 * T[:, None] / 3.0
    if noise.gyro_quantization:
        # each sample's specific force is rotated with the indicated attitude: the mean of n independent
        # angle errors Q tilts the keyframe's (the attitude at its start holds its own)
        var[:, :2] += ((record.gravity * noise.gyro_quantization) ** 2 / np.diff(record.k0))[:, None]
    if "lever_arm" in layout:
        # the boundary rates' scatter (model.local_rates: a ring-laser gyro's quantization leaves some at a
        # ramp, where a short fit is kept) through the lever-arm term, C (dw x l) at each end, taken isotropic
        # with the lever arm of the linearisation point (fixed while the preintegration is)
        l_lin = layout.get(preint.x_lin, "lever_arm", np.zeros(3))
        sw = record.w_b_sigma
        var += ((2.0 / 3.0) * float(l_lin @ l_lin) * np.sum(sw[:-1] ** 2 + sw[1:] ** 2, axis=1) / (3.0 * T**2))[:, None]
    if sway_sigma:
        var += float(sway_sigma) ** 2
    sigma = np.sqrt(var)
    if moving_sigma is not None:
        sigma[~record.static_key] = np.maximum(sigma[~record.static_key], moving_sigma)
    return Residuals(r=r, key=np.arange(K), H_R=H_R, H_R_next=None, H_x=H_x, sigma=sigma)

def encoder_factors(record, R, preint, x, *, layout, noise):
    """Gyro attitude against every valid table reading, rad; ``R`` (K+1 or K, 3, 3).

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
    R : ndarray, shape (K+1, 3, 3) or (K, 3, 3)
    preint : graph_calib.model.preintegration.Preintegrated
    x : ndarray, shape (P,)
    layout : graph_calib.sensors.params.Layout
    noise : Noise

    Returns
    -------
    Residuals
    """
    M = record.reading_sample.size
    P = layout.size
    if M == 0:
        z = np.zeros((0, 3))
        return Residuals(r=z, key=np.zeros(0, dtype=np.int64), H_R=np.zeros((0, 3, 3)), H_R_next=None,
                         H_x=np.zeros((0, 3, P)), sigma=z)
    # reading by reading, in the compiled kernel (graph_calib.model.encoder_kernel); the reading noise in its
    # principal axes (graph_calib.model.encoder_noise): residual and Jacobians turned by the data-only U^T, each
    # component then independent with its own sigma
    frame = record.encoder_noise_frame(noise.encoder)
    r = np.empty((M, 3))
    H_R = np.empty((M, 3, 3))
    H_x = np.zeros((M, 3, P))
    _encoder_rows(record, R, preint, x, layout, frame, r, H_R, H_x)
    parts = encoder_variance(record, noise)
    sigma = np.sqrt(parts.own + parts.floor + parts.gyro[:, None])
    return Residuals(r=r, key=record.reading_key.copy(), H_R=H_R, H_R_next=None, H_x=H_x, sigma=sigma)


@dataclass(frozen=True)
class EncoderVariance:
    """The three parts of each table reading's variance, rad^2, each with its own variance factor.

    Attributes
    ----------
    own : ndarray, shape (M, 3)
        The reading's own noise along its noise frame (a dwell's scatter or the declared noise, and a ring-laser
        gyro's quantization at the reading) times the ``encoder`` factor; of a floored component only the
        quantization (its floor is apart).
    floor : ndarray, shape (M, 3)
        The floor of each floored component times the :data:`graph_calib.model.encoder_noise.FLOORED` factor,
        zero elsewhere.
    gyro : ndarray, shape (M,)
        The gyro's noise from the keyframe to the reading, ``q_g^2 tau``, times the ``rotation`` factor: the
        gyro's, the same noise as the rotation factor's (:mod:`graph_calib.model.shared_gyro_noise`).
    """

    own: np.ndarray
    floor: np.ndarray
    gyro: np.ndarray


def encoder_variance(record, noise):
    """The :class:`EncoderVariance` of every valid reading of ``record`` under ``noise`` (its factors applied)."""
    frame = record.encoder_noise_frame(noise.encoder)
    vf = noise.variance_factors
    v_enc = float(vf.get("encoder", 1.0))
    own = v_enc * np.where(frame.floored, 0.0, frame.var)
    if noise.gyro_quantization:
        own = own + (v_enc * noise.gyro_quantization**2 * record.reading_quantization_gain)[:, None]
    floor = float(vf.get(FLOORED, 1.0)) * np.where(frame.floored, frame.var, 0.0)
    gyro = float(vf.get("rotation", 1.0)) * noise.gyro**2 * record.reading_tau
    return EncoderVariance(own=own, floor=floor, gyro=gyro)


def _column(layout, name):
    """First layout column of ``name``, -1 when the layout lacks it."""
    return layout.slice(name).start if name in layout else -1


def encoder_columns(layout, preint):
    """The calibration columns an encoder factor's Jacobian can touch (sorted int64): the gyro columns of the
    preintegration, ``mount``, ``time_lag.table`` and ``damping.stiffness``; every other column of its ``H_x``
    is zero."""
    cols = [_column(layout, n) for n in ("mount", "time_lag.table", "damping.stiffness")]
    spans = [np.arange(c, c + k) for c, k in zip(cols, (3, 1, 9)) if c >= 0]
    return np.unique(np.concatenate([np.asarray(preint.gyro_cols, dtype=np.int64), *spans])).astype(np.int64)


def _encoder_rows(record, R, preint, x, layout, frame, r, H_R, H_x):
    """:func:`graph_calib.model.encoder_kernel.encoder_rows` on every reading of ``record``: ``r`` (M, 3),
    ``H_R`` (M, 3, 3) and the model's columns of ``H_x`` (M, 3, P, zero on entry) written."""
    x = np.asarray(x, dtype=float)
    gc = np.ascontiguousarray(preint.gyro_cols, dtype=np.int64)
    dx_g = np.ascontiguousarray((x - preint.x_lin)[gc])
    mount = np.ascontiguousarray(layout.get(x, "mount", np.zeros(3)), dtype=float)
    lag = float(layout.get(x, "time_lag.table", np.zeros(1))[0])
    K_damp = np.ascontiguousarray(layout.get(x, "damping.stiffness", np.zeros(9)), dtype=float).reshape(3, 3)
    cols = [_column(layout, n) for n in ("mount", "time_lag.table", "damping.stiffness")]
    written = encoder_columns(layout, preint)
    c = np.ascontiguousarray
    encoder_rows(c(preint.reading_dR), c(preint.reading_w), c(preint.reading_J), c(preint.reading_rate_jacobian()),
                 dx_g, c(record.reading_dt), c(record.reading_phi_shape), c(record.reading_key, dtype=np.int64),
                 c(record.reading_E), c(R, dtype=float), c(record.reading_w_nb_offset), c(record.reading_alpha),
                 c(record.reading_f), c(record.reading_C_nb_nominal), mount, lag, K_damp, bool(np.any(K_damp)), gc,
                 cols[0], cols[1], cols[2], written, c(frame.U), c(frame.rotated), r, H_R, H_x)


@dataclass(frozen=True)
class PriorResidual:
    """A Gaussian prior as a whitened residual, like every other factor (navlie's ``PriorResidual``).

    Attributes
    ----------
    r : ndarray, shape (n,)
        Whitened residual at the evaluation point.
    H : ndarray, shape (n, n)
        Its Jacobian in the variable's perturbation (right perturbation for a rotation).
    sigma : ndarray, shape (n,)
        The prior's one sigma per component (SI).
    """

    r: np.ndarray
    H: np.ndarray
    sigma: np.ndarray

    @property
    def cost(self):
        """Half the squared norm of the whitened residual."""
        return 0.5 * float(self.r @ self.r)


def attitude_prior(R0, *, R_prior, sigma):
    """The prior of the first keyframe attitude: ``Log(R_prior^T R0) / sigma``.

    Parameters
    ----------
    R0 : ndarray, shape (3, 3)
        First keyframe attitude ``C_nb``.
    R_prior : ndarray, shape (3, 3)
        The alignment.
    sigma : float
        Isotropic prior sigma, rad.

    Returns
    -------
    PriorResidual
        Jacobian ``Jr^-1(r) / sigma`` in the right perturbation of ``R0``.
    """
    e = log_so3(R_prior.T @ R0)
    return PriorResidual(r=e / sigma, H=right_jacobian_inv(e) / sigma, sigma=np.full(3, float(sigma)))


def calibration_prior(x, *, mean, sigma):
    """The prior of the calibration vector: ``(x - mean) / sigma``, Jacobian ``diag(1 / sigma)``."""
    sigma = np.asarray(sigma, dtype=float)
    inv = 1.0 / sigma                         # as GTSAM's diagonal noise model whitens: by 1 / sigma
    return PriorResidual(r=(np.asarray(x, dtype=float) - mean) * inv, H=np.diag(inv), sigma=sigma)


def sum_by_key(target, key, vals):
    """``target[key[i]] += vals[i]``, duplicates summed: a factor kind's terms into its keyframes' blocks.

    Keys in non-decreasing order (every factor kind's are) are summed by one ``np.add.reduceat`` per run
    of equal keys (``np.add.at`` took half the time of a 3 h experiment's linearisation); other orders
    fall back to ``np.add.at``.

    Parameters
    ----------
    target : ndarray, shape (n, ...)
    key : ndarray of int, shape (F,)
    vals : ndarray, shape (F, ...)
    """
    if key.size == 0:
        return
    if np.any(key[1:] < key[:-1]):
        np.add.at(target, key, vals)
        return
    starts = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
    target[key[starts]] += np.add.reduceat(vals, starts, axis=0)


__all__ = ["Noise", "Residuals", "PriorResidual", "rotation_factors", "still_factors", "gravity_factors", "encoder_factors",
           "EncoderVariance", "encoder_variance", "encoder_columns", "attitude_prior", "calibration_prior", "sum_by_key"]
