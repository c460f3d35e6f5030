r"""What the IMU measures: true rates and specific force, sensor errors, increments.

True signals (``model.md``), at any time, from the exact kinematics of the motion:

.. math::

    \omega_{ib}^b = \omega_{nb}^b + C_{nb}^T\omega_{ie}^n,

    f^b = C_{nb}^T\big([0, 0, g] + a^n + 2\,\omega_{ie}^n \times v^n\big)
          + \dot\omega_{nb}^b \times l + \omega_{nb}^b \times (\omega_{nb}^b \times l)
          + 2\,(C_{nb}^T\omega_{ie}^n) \times (\omega_{nb}^b \times l),

with ``l`` the lever arm (in ``b``), ``a^n``, ``v^n`` the acceleration and
velocity of the rotation centre (zero on a turntable) and the last term the
Coriolis force of the lever-arm point's velocity ``C_nb (omega_nb_b x l)``.

``damping.stiffness`` (``K``) is not a term of the sensor model: the sensor
block ``b`` tilts on its dampers against the housing ``h`` (bolted to the
faceplate) by ``delta = K f^b``, so ``C_nb = C_nh Exp(delta)``, and the
sensors see ``omega_ib_b = Exp(delta)^T omega_ih_h + Jr(delta) d(delta)/dt``
and ``f_b = Exp(delta)^T f_h``.  ``delta`` is found by one fixed-point step
from ``K f_h`` (the rest is below ``|K|^2 g`` ~ 1e-11 rad); ``d(delta)/dt = K
df/dt`` with ``df/dt`` by a central difference (step 1 % of a sample period,
inside one smooth segment); the lever arm is applied in the housing axes and
the tilt's own angular acceleration is left out of the size-effect term (both
of relative order ``|delta|`` ~ 1e-5 of an effect that is itself small).

Sensor errors come from :func:`graph_calib.sensors.sensor_model.measure`, with
``dT = T - T_ref`` and ``dT/dt`` of each sensor at the same instant.

Increments are the integrals of the measured rate and specific force over each
sample interval ``(t[k-1], t[k]]``, by Gauss-Legendre quadrature with
``n_nodes`` nodes per interval (default 3, exact for polynomials of degree 5).
Every motion segment starts and ends on the sample grid, so each interval lies
inside one analytic piece and the quadrature error is at the level of rounding
(see ``docs/simulator.md`` for the measured accuracy).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib.constants import omega_ie_n
from graph_calib.navigation.rotations import exp_so3, right_jacobian
from graph_calib.sensors.sensor_model import measure

def _cross(a, b):
    """Row-wise cross product of (N, 3) arrays (either may be (1, 3))."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.column_stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


#: Samples per chunk of vectorised work (bounds the memory to some tens of MB).
CHUNK = 32768


class SignalModel:
    """True signals of a motion at any time.

    Parameters
    ----------
    motion : TurntableMotion or HandheldMotion
        Anything with ``kinematics(t)``.
    latitude_rad, gravity_mps2 : float
    lever_arm : array_like, shape (3,)
        m, in ``b``.
    stiffness : array_like, shape (3, 3), optional
        ``damping.stiffness`` matrix ``K`` (rad per m/s^2), row-major as in the catalogue.
    rate_hz : float
        Sample rate (sets the finite-difference step for ``df/dt``).
    """

    def __init__(self, motion, *, latitude_rad, gravity_mps2, lever_arm=None, stiffness=None, rate_hz=100.0):
        self.motion = motion
        self.w_ie_n = omega_ie_n(latitude_rad)
        self.g = float(gravity_mps2)
        self.lever = np.zeros(3) if lever_arm is None else np.asarray(lever_arm, dtype=float)
        K = None if stiffness is None else np.asarray(stiffness, dtype=float).reshape(3, 3)
        self.K = None if K is None or not np.any(K) else K
        self.h_fd = 0.01 / float(rate_hz)

    def _housing(self, t):
        """Housing attitude, rates and specific force (no damper tilt)."""
        k = self.motion.kinematics(t)
        C = k.C_nb
        w, dw = k.omega_nb_b, k.domega_nb_b
        wi = self.w_ie_n
        w_ie_b = wi[0] * C[:, 0, :] + wi[1] * C[:, 1, :] + wi[2] * C[:, 2, :]  # C^T omega_ie_n
        if k.acc_n is None:
            f = self.g * C[:, 2, :]  # C^T [0, 0, g]
        else:
            f_n = k.acc_n + _cross(wi[None, :], 2.0 * k.vel_n)
            f_n[:, 2] += self.g
            f = f_n[:, 0:1] * C[:, 0, :] + f_n[:, 1:2] * C[:, 1, :] + f_n[:, 2:3] * C[:, 2, :]
        if np.any(self.lever):
            wl = _cross(w, self.lever[None, :])
            f = f + _cross(dw, self.lever[None, :]) + _cross(w + 2.0 * w_ie_b, wl)
        return C, w, dw, w + w_ie_b, f

    def _df(self, t):
        h = self.h_fd
        return (self._housing(t + h)[4] - self._housing(t - h)[4]) / (2.0 * h)

    def signals(self, t, *, derivative=False):
        """True signals at ``t``.

        Returns
        -------
        dict
            ``C_nb`` (N, 3, 3), ``omega_nb_b``, ``domega_nb_b``, ``omega_ib_b``,
            ``f_b`` (N, 3), and ``df_b`` (N, 3) when ``derivative`` is true or
            the damper tilt needs it.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        C, w, dw, w_ib, f = self._housing(t)
        df = self._df(t) if (derivative or self.K is not None) else None
        if self.K is not None:
            delta = f @ self.K.T
            E = exp_so3(delta)
            delta = np.einsum("nji,nj->ni", E, f) @ self.K.T  # one fixed-point step: K f_b
            E = exp_so3(delta)
            ddelta = df @ self.K.T
            Jd = np.einsum("nij,nj->ni", right_jacobian(delta), ddelta)
            Et = np.swapaxes(E, 1, 2)
            C = C @ E
            w = np.einsum("nij,nj->ni", Et, w) + Jd
            dw = np.einsum("nij,nj->ni", Et, dw)
            w_ib = np.einsum("nij,nj->ni", Et, w_ib) + Jd
            f = np.einsum("nij,nj->ni", Et, f)
            df = np.einsum("nij,nj->ni", Et, df)
        out = {"C_nb": C, "omega_nb_b": w, "domega_nb_b": dw, "omega_ib_b": w_ib, "f_b": f}
        if df is not None:
            out["df_b"] = df
        return out

    def attitude(self, t):
        """True ``C_nb`` at ``t`` (damper tilt included), shape (N, 3, 3)."""
        return self.signals(t)["C_nb"] if self.K is not None else self.motion.kinematics(t).C_nb


def simulate_increments(signal_model, thermal, *, rate_hz, n_samples, layout, x, t_ref, temperature_map,
                        n_nodes=3, chunk=CHUNK):
    """Noise-free increments ``dtheta``, ``dv`` of the measured rates and specific forces.

    Sample ``k`` (0-based) is stamped ``t[k] = (k + 1) / rate_hz`` and covers
    ``(k / rate_hz, (k + 1) / rate_hz]``.

    Parameters
    ----------
    signal_model : SignalModel
    thermal : ThermalModel
    rate_hz : float
    n_samples : int
    layout : graph_calib.sensors.params.Layout
        Every parameter the data are made with.
    x : ndarray, shape (layout.size,)
    t_ref : float
        Reference temperature of ``x``, degC.
    temperature_map : array_like of int, shape (6,)
    n_nodes : int
        Gauss-Legendre nodes per sample interval.
    chunk : int
        Samples per vectorised block.

    Returns
    -------
    t : ndarray, shape (N,)
    dtheta, dv : ndarray, shape (N, 3)
    """
    xi, wq = np.polynomial.legendre.leggauss(int(n_nodes))
    frac = 0.5 * (1.0 + xi)           # node position inside the interval, in periods
    wq = 0.5 * wq                      # weights for an interval of length 1 period
    tmap = np.asarray(temperature_map, dtype=int)
    used, inv = np.unique(tmap, return_inverse=True)  # only the channels the sensors use
    x = np.asarray(x, dtype=float)
    names = set(layout.names)
    need_df = "time_lag.accel" in names
    need_dT = any(n.endswith(("_tc", "_tc2")) for n in names)
    need_dTdt = any(n.endswith("_dtdt") for n in names)
    dt = 1.0 / float(rate_hz)
    dtheta = np.empty((n_samples, 3))
    dv = np.empty((n_samples, 3))
    for a in range(0, n_samples, chunk):
        b = min(n_samples, a + chunk)
        k = np.arange(a, b, dtype=float)
        tn = ((k[:, None] + frac[None, :]) / float(rate_hz)).ravel()
        s = signal_model.signals(tn, derivative=need_df)
        dT = dTdt = None
        if need_dT:
            dT = thermal.temperature(tn, used)[:, inv] - t_ref
        if need_dTdt:
            dTdt = thermal.rate(tn, used)[:, inv]
        m_g = measure(layout, x, "gyro", s["omega_ib_b"],
                      dT=None if dT is None else dT[:, :3], dTdt=None if dTdt is None else dTdt[:, :3],
                      other=s["f_b"])
        m_a = measure(layout, x, "accel", s["f_b"],
                      dT=None if dT is None else dT[:, 3:], dTdt=None if dTdt is None else dTdt[:, 3:],
                      other=s["omega_nb_b"], domega=s["domega_nb_b"], dsignal=s.get("df_b"))
        nb = b - a
        dtheta[a:b] = dt * np.einsum("knj,n->kj", m_g.reshape(nb, n_nodes, 3), wq)
        dv[a:b] = dt * np.einsum("knj,n->kj", m_a.reshape(nb, n_nodes, 3), wq)
    t = np.arange(1, n_samples + 1) / float(rate_hz)
    return t, dtheta, dv


@dataclass(frozen=True)
class SensorNoiseSpec:
    """The white noise a simulated record gets.

    Attributes
    ----------
    gyro : float
        Angle random walk, rad/sqrt(s).
    accel : float
        Velocity random walk, m/s/sqrt(s).
    gyro_quantization : float
        A white error of the angle itself (a ring-laser gyro's pulse quantization, dither-randomised), one
        sigma, rad: each increment gets the difference of two consecutive such errors (IEEE Std 952 ``Q``).
    accel_quantization : float
        The same for the velocity, m/s.
    """

    gyro: float
    accel: float
    gyro_quantization: float = 0.0
    accel_quantization: float = 0.0


def add_sensor_noise(dtheta, dv, spec, *, dt, rng, rng_quantization=None):
    """Add ``spec``'s noise to the increments in place.

    The white noise is drawn from ``rng`` exactly as before quantization existed (gyro, then
    accelerometer), so a record without quantization keeps its draws; the quantization errors come
    from ``rng_quantization`` (needed when any is set).
    """
    dtheta += spec.gyro * np.sqrt(dt) * rng.standard_normal(dtheta.shape)
    dv += spec.accel * np.sqrt(dt) * rng.standard_normal(dv.shape)
    for inc, q in ((dtheta, spec.gyro_quantization), (dv, spec.accel_quantization)):
        if q > 0:
            e = q * rng_quantization.standard_normal((inc.shape[0] + 1, inc.shape[1]))
            inc += np.diff(e, axis=0)


__all__ = ["SignalModel", "simulate_increments", "SensorNoiseSpec", "add_sensor_noise", "CHUNK"]
