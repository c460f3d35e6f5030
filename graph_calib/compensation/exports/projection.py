r"""The full model projected onto what a format can hold, and what that leaves out, with its size.

Every export evaluates the full model (:meth:`ExportSource.errors`) on a grid over
the calibrated temperature range and over an envelope of signals, and compares it
with what the format's own equation restores:

Envelope
    Angular rates of magnitude 0 and :data:`DEFAULT_ENVELOPE_DPS` (deg/s) along 26
    directions (the axes, the face and the space diagonals) combined with a specific
    force of 1 g along the same 26 directions: a vehicle at rest in any attitude, or
    turning at up to that rate.  The largest remaining error over the grid and the
    envelope, per triad and over its three axes, is the *loss* each export reports
    (deg/h and micro-g).

Bias-only formats (PX4, ArduPilot)
    :func:`bias_cubic`: the bias (the error at zero rate and zero specific force) of
    each axis as a cubic in ``T - T_ref``, least squares over the grid.  Everything
    else (scale, misalignment, their temperature dependence, g-sensitivity and any
    further effect) is left out.

Constant-intrinsics formats (Kalibr, OpenVINS)
    :func:`intrinsics`: the linear part of the model at the reference temperature,
    ``m_g = A_g omega + G f + b_g``, ``m_a = A_a f + b_a``, written in the
    accelerometer frame as lower-triangular ``M_a``, ``M_g`` and a rotation ``C``
    (``A_a = M_a R``, ``A_g R^T = M_g C``, ``G_i = G R^T``, ``R`` the rotation from
    graph-calib's body frame to that frame).  The biases are estimated online by those
    estimators and are not written; their change over the range is reported.  Left out:
    the intrinsics' temperature dependence and any non-linear effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib import constants as c

#: Rate envelope of the reported loss, deg/s (the ``--envelope-dps`` default).
DEFAULT_ENVELOPE_DPS = 100.0
#: Grid step over the calibrated range, degC (at least :data:`MIN_GRID_POINTS` points).
GRID_STEP_DEGC = 0.25
MIN_GRID_POINTS = 41
#: Parameters a bias-only format holds.
BIAS_PARAMETERS = ("gyro.bias", "accel.bias", "gyro.bias_tc", "accel.bias_tc", "gyro.bias_tc2", "accel.bias_tc2",
                   "gyro.bias_tc3", "accel.bias_tc3")
#: Parameters a constant-intrinsics format holds (the biases go to the estimator's online states).
INTRINSIC_PARAMETERS = ("gyro.bias", "accel.bias", "gyro.scale", "accel.scale", "gyro.misalignment",
                        "accel.misalignment", "gyro.g_sensitivity")


def directions():
    """The 26 unit directions of the envelope: axes, face diagonals and space diagonals."""
    d = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)],
                 dtype=float)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def grid(range_degC):
    """Temperatures over the calibrated range, degC."""
    lo, hi = range_degC
    n = max(MIN_GRID_POINTS, int(np.ceil((hi - lo) / GRID_STEP_DEGC)) + 1)
    return np.linspace(lo, hi, n)


def envelope(envelope_dps=DEFAULT_ENVELOPE_DPS):
    """``(omega_b, f_b)`` (M, 3) of the envelope (module docstring)."""
    d = directions()
    rates = np.vstack([np.zeros((1, 3)), d * envelope_dps * c.DEG_TO_RAD])
    omega = np.repeat(rates, d.shape[0], axis=0)
    f = np.tile(d * c.G0, (rates.shape[0], 1))
    return omega, f


@dataclass(frozen=True)
class Loss:
    """The largest remaining error of an export over the range and the envelope.

    Attributes
    ----------
    gyro_degph, accel_ug : float
        Over the grid, the envelope and the three axes.
    at_degC : tuple of float
        Temperature of each (gyro, accel).
    left_out : tuple of str
        Parameters of the calibration the format cannot hold.
    range_degC : tuple of float
    envelope_dps : float
    extra : tuple of str
        Further lines (e.g. what the estimator's online bias must cover).
    """

    gyro_degph: float
    accel_ug: float
    at_degC: tuple
    left_out: tuple
    range_degC: tuple
    envelope_dps: float
    extra: tuple = ()

    def lines(self):
        """The report in words: for the file's comments and the terminal."""
        lo, hi = self.range_degC
        out = [f"left out: {', '.join(self.left_out) if self.left_out else 'nothing'}",
               f"largest remaining error over {lo:.2f}..{hi:.2f} degC, |omega| <= {self.envelope_dps:g} deg/s, "
               f"|f| = 1 g in any direction: gyro {self.gyro_degph:.4g} deg/h (at {self.at_degC[0]:.2f} degC), "
               f"accel {self.accel_ug:.4g} micro-g (at {self.at_degC[1]:.2f} degC)"]
        return out + list(self.extra)


def remaining(source, restored, *, envelope_dps=DEFAULT_ENVELOPE_DPS, left_out=(), extra=()):
    """The :class:`Loss` of a format whose equation restores ``restored(T, omega, f) -> (e_gyro, e_accel)``.

    ``restored`` is the error the format removes (what its consumer subtracts, as a sensor error); the loss is
    ``max |full error - restored|`` over the grid and the envelope.
    """
    T = grid(source.range_degC)
    omega, f = envelope(envelope_dps)
    m = omega.shape[0]
    TT = np.repeat(T, m)
    W = np.tile(omega, (T.size, 1))
    F = np.tile(f, (T.size, 1))
    eg, ea = source.errors(TT, W, F)
    rg, ra = restored(TT, W, F)
    dg = np.abs(eg - rg).max(axis=1)
    da = np.abs(ea - ra).max(axis=1)
    ig, ia = int(np.argmax(dg)), int(np.argmax(da))
    return Loss(gyro_degph=float(dg[ig] * c.RS_TO_DH), accel_ug=float(da[ia] * c.MPS2_TO_UG),
                at_degC=(float(TT[ig]), float(TT[ia])), left_out=tuple(left_out), range_degC=tuple(source.range_degC),
                envelope_dps=float(envelope_dps), extra=tuple(extra))


def bias_cubic(source, t_ref_degC, *, dtype=np.float32):
    """Bias of each axis as a cubic in ``T - t_ref_degC``: ``(gyro (4, 3), accel (4, 3))``, coefficient i of order i.

    Least squares over :func:`grid`; the coefficients rounded to ``dtype`` (the autopilots' float32).
    """
    T = grid(source.range_degC)
    z = np.zeros((T.size, 3))
    eg, ea = source.errors(T, z, z)
    V = np.vander(T - t_ref_degC, 4, increasing=True)
    cg = np.linalg.lstsq(V, eg, rcond=None)[0]
    ca = np.linalg.lstsq(V, ea, rcond=None)[0]
    return cg.astype(dtype).astype(float), ca.astype(dtype).astype(float)


def cubic(coefficients, dT):
    """``sum_i c_i dT^i`` per axis: ``coefficients`` (4, 3), ``dT`` (N,) -> (N, 3)."""
    return np.vander(np.asarray(dT, dtype=float), 4, increasing=True) @ coefficients


def left_out(source, held):
    """Parameters of the calibration outside ``held`` (bench parameters are never a sensor correction)."""
    from graph_calib.compensation.elements import TABLE_PARAMETERS
    return tuple(p for p in source.parameters() if p not in held and (p in TABLE_PARAMETERS or "_tc" in p))


def _lower_rotation(A):
    """``A = L Q``: L lower triangular with a positive diagonal, Q a rotation."""
    q, r = np.linalg.qr(A.T)          # A^T = q r  ->  A = r^T q^T
    s = np.sign(np.diag(r))
    s[s == 0] = 1.0
    q, r = q * s, (r.T * s).T
    L, Q = r.T, q.T
    if np.linalg.det(Q) < 0:          # a reflection: not a frame change (never for a calibration near identity)
        raise ValueError("the linear part is not a scale-misalignment of a right-handed frame")
    return L, Q


@dataclass(frozen=True)
class Intrinsics:
    """The linear part of the model at one temperature, in the accelerometer frame (module docstring)."""

    M_a: np.ndarray
    M_g: np.ndarray
    C_gyro_i: np.ndarray
    G_i: np.ndarray
    R_body_to_imu: np.ndarray
    b_g: np.ndarray
    b_a: np.ndarray
    t_degC: float

    def rotation_deg(self):
        """Angle of the rotation from graph-calib's body frame to the file's IMU frame, degrees."""
        return float(np.degrees(np.arccos(np.clip((np.trace(self.R_body_to_imu) - 1.0) / 2.0, -1.0, 1.0))))


def intrinsics(source, t_degC, *, step_rad_s=0.5, step_mps2=5.0):
    """:class:`Intrinsics` at ``t_degC``: the model's linear part by central differences over the signals."""
    T = np.full(1, float(t_degC))
    z = np.zeros((1, 3))
    bg, ba = (e[0] for e in source.errors(T, z, z))
    I3 = np.eye(3)
    A_g, G, A_a = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for j in range(3):
        hw, hf = I3[j] * step_rad_s, I3[j] * step_mps2
        gp, _ = source.errors(T, hw[None], z)
        gm, _ = source.errors(T, -hw[None], z)
        A_g[:, j] = I3[j] + (gp[0] - gm[0]) / (2 * step_rad_s)
        gp, ap = source.errors(T, z, hf[None])
        gm, am = source.errors(T, z, -hf[None])
        G[:, j] = (gp[0] - gm[0]) / (2 * step_mps2)
        A_a[:, j] = I3[j] + (ap[0] - am[0]) / (2 * step_mps2)
    M_a, R = _lower_rotation(A_a)
    M_g, C = _lower_rotation(A_g @ R.T)
    return Intrinsics(M_a=M_a, M_g=M_g, C_gyro_i=C, G_i=G @ R.T, R_body_to_imu=R, b_g=bg, b_a=ba,
                      t_degC=float(t_degC))


def intrinsics_restored(source, intr):
    """What an estimator with these constant intrinsics and a perfect online bias restores, as sensor errors.

    The online bias is the full model's bias at each temperature (what the estimator tracks); the rest is
    ``A_g omega + G f - omega`` and ``A_a f - f`` in graph-calib's body frame.
    """
    R = intr.R_body_to_imu
    A_g = intr.M_g @ intr.C_gyro_i @ R
    A_a = intr.M_a @ R
    G = intr.G_i @ R

    def restored(T, omega, f):
        z = np.zeros_like(omega)
        bg, ba = source.errors(T, z, z)
        return bg + omega @ (A_g - np.eye(3)).T + f @ G.T, ba + f @ (A_a - np.eye(3)).T
    return restored


__all__ = ["DEFAULT_ENVELOPE_DPS", "Loss", "remaining", "bias_cubic", "cubic", "left_out", "Intrinsics", "intrinsics",
           "intrinsics_restored", "grid", "envelope", "directions", "BIAS_PARAMETERS", "INTRINSIC_PARAMETERS"]
