r"""Guided full turns: a Ferraris session's turns about the vertical, slid flat and pressed against a guide.

A Ferraris calibration (imucal's guide, ``ModelOptions.guided_turns``) turns the unit a whole number of times
about the vertical while it lies flat on a level surface, pressed against a fixed guide (a box) before and
after.  Two facts of that protocol say more than the gyros' integral between two rests does, and without
them a turn about the vertical tells gravity nothing of the gyro: its scale about the vertical changes the
heading alone, and a misaligned axis only tilts the unit in a circle that closes at the end of the turn.

- **Closure**: the unit ends where it began: ``R_b = R_a`` (level frame; the Earth's turn over the interval
  in ``E``).
- **Flat**: through the turn the unit's vertical stays the rest's: at every keyframe boundary ``j`` inside
  it, ``R_j^T n_z = R_a^T n_z``.

Both are written on the attitude before the turn and the calibration alone, with the turn's keyframe
rotations chained (``R_j = E_{a->j} R_a Pi_j(x)``, ``Pi_j = dR_a ... dR_{j-1}``), so each is a measurement of
one keyframe (``R_a``) as the model's other measurements are, which the filter and the graph take alike.  The
gyro noise over the turn is then counted in these factors beside the rotation factors of the same keyframes;
it is added to their variance, and it is small against the protocol's own (0.01 deg against 0.5 deg over a
4 s turn of a consumer gyro).

Per turn, one factor of three rows for the closure ``Log(R_b_hat^T R_a)``, and one per inside boundary
whose first two rows are the tilt ``B^T (R_j_hat^T n_z - R_a^T n_z)`` on a basis ``B`` of the plane normal to
the rest's raw specific force (data: the vertical in the body within the accelerometer's errors; the dropped
component along it is of second order) and whose third row is weightless
(``sigma`` infinite, residual and Jacobian zero; :mod:`graph_calib.model.redundancy` counts no redundancy
for it).

A turn is found (:func:`find_guided_turns`) where a run of moving keyframes between two static ones of one
segment (the turn taken from the start of the one before to the end of the one after) has the rests' specific
force on one face (within :data:`FACE_TOLERANCE_DEG`), a raw gyro angle
vector of at least :data:`MIN_TURN_DEG` within :data:`AXIS_TOLERANCE_DEG` of that vertical, and a raw rotation
within :data:`CLOSURE_TOLERANCE_DEG` of a whole number of turns (a consumer gyro's scale error of a few per
cent leaves 20 deg of a 360 deg turn).
"""

from __future__ import annotations

import numpy as np

from graph_calib.model.factors import Residuals
from graph_calib.navigation.rotations import log_so3, quat_to_rotvec, right_jacobian_inv, skew
from graph_calib.navigation.strapdown import integrate_attitude

#: The factor kind's name (:data:`graph_calib.model.residual_list.FACTOR_KINDS`).
KIND = "turn"
#: The two rests of a guided turn lie on one face: their specific forces within this angle, deg.
FACE_TOLERANCE_DEG = 5.0
#: A guided turn's raw gyro angle (the integral of the rate vector), at least, deg.
MIN_TURN_DEG = 300.0
#: Its direction within this angle of the rests' vertical, deg.
AXIS_TOLERANCE_DEG = 15.0
#: Its raw rotation within this angle of the identity, deg.
CLOSURE_TOLERANCE_DEG = 30.0
#: The protocol's one sigma per axis when ``guided_turns`` is True: a hand pressing a unit against a guide
#: and sliding it flat, rad (0.5 deg).
DEFAULT_SIGMA = np.deg2rad(0.5)


def _angle_deg(u, v):
    c = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _raw_turn_deg(record, start, stop):
    """The angle, deg, by which the raw increments of samples ``[start, stop)`` turn the unit in the level frame
    (:func:`graph_calib.navigation.strapdown.integrate_attitude`: coning and the Earth rate in)."""
    e = record.experiment
    q = integrate_attitude(e.dtheta[start:stop], t=e.t[start:stop], rate_hz=e.rate_hz, q_nb0=[1.0, 0.0, 0.0, 0.0],
                           latitude_rad=e.latitude_rad)
    return float(np.degrees(np.linalg.norm(quat_to_rotvec(q[-1]))))


def find_guided_turns(record):
    """The guided full turns of a prepared record (module docstring).

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
        With its rests known (``static_known``).

    Returns
    -------
    ndarray of int, shape (T, 2)
        Keyframe boundaries ``(a, b)`` of each turn: ``R_a`` starts the last static keyframe before the motion,
        ``R_b`` ends the first static keyframe after it.
    """
    if not record.static_known:
        return np.zeros((0, 2), dtype=np.int64)
    static = np.asarray(record.static_key, dtype=bool)
    K = static.size
    segment = np.zeros(K, dtype=np.int64)
    segment[record.segment_keys[1:]] = 1
    segment = np.cumsum(segment)
    k0 = record.k0
    out = []
    k = 1
    while k < K:
        if static[k] or not static[k - 1]:
            k += 1
            continue
        m0 = k
        while k < K and not static[k]:
            k += 1
        m1 = k
        if m1 >= K or segment[m0 - 1] != segment[m1]:
            continue
        # from the start of the last static keyframe before the motion to the end of the first one after: a rest's
        # edge keyframe may hold the slow start (end) of a smooth turn, which the rests' detector cannot tell from
        # rest where the specific force does not change
        a, b = m0 - 1, m1 + 1
        f_before = record.f_raw[k0[a]:k0[a + 1]].mean(axis=0)
        f_after = record.f_raw[k0[b - 1]:k0[b]].mean(axis=0)
        w, dt = record.w_raw[k0[a]:k0[b]], record.dt[k0[a]:k0[b]]
        angle = np.sum(w * dt[:, None], axis=0)
        if (_angle_deg(f_before, f_after) > FACE_TOLERANCE_DEG
                or np.degrees(np.linalg.norm(angle)) < MIN_TURN_DEG
                or min(_angle_deg(angle, f_before), _angle_deg(angle, -f_before)) > AXIS_TOLERANCE_DEG
                or _raw_turn_deg(record, k0[a], k0[b]) > CLOSURE_TOLERANCE_DEG):
            continue
        out.append((a, b))
    return np.asarray(out, dtype=np.int64).reshape(-1, 2)


def _plane_basis(u):
    """Two orthonormal vectors normal to the unit vector ``u`` (3,), as columns (3, 2)."""
    e = np.eye(3)[int(np.argmin(np.abs(u)))]
    e1 = np.cross(u, e)
    e1 /= np.linalg.norm(e1)
    return np.column_stack([e1, np.cross(u, e1)])


def turn_factors(record, R, preint, x, *, turns, sigma, gyro_noise):
    """The closure and flat factors of the guided turns ``turns`` (module docstring).

    Parameters
    ----------
    record : graph_calib.model.record.PreparedRecord
    R : ndarray, shape (K+1, 3, 3)
        Keyframe attitudes ``C_nb``.
    preint : graph_calib.model.preintegration.Preintegrated
    x : ndarray, shape (P,)
    turns : ndarray of int, shape (T, 2)
        :func:`find_guided_turns`.
    sigma : float
        The protocol's one sigma per axis, rad.
    gyro_noise : float
        The gyros' white noise, rad/sqrt(s) (its integral over the turn adds to each factor's variance).

    Returns
    -------
    Residuals
        ``key`` the turns' ``a``; ``H_R_next`` None.
    """
    P = np.asarray(x).size
    n_rows = int(np.sum(turns[:, 1] - turns[:, 0])) if turns.size else 0
    r = np.zeros((n_rows, 3))
    key = np.zeros(n_rows, dtype=np.int64)
    H_R = np.zeros((n_rows, 3, 3))
    H_x = np.zeros((n_rows, 3, P))
    sig = np.full((n_rows, 3), np.inf)
    if n_rows == 0:
        return Residuals(r=r, key=key, H_R=H_R, H_R_next=None, H_x=H_x, sigma=sig)
    c = preint.corrected(x)
    E = record.earth_turn(record.T_key)
    n_z = np.array([0.0, 0.0, 1.0])
    row = 0
    for a, b in turns:
        Ra = R[a]
        up_a = Ra.T @ n_z
        f_rest = record.f_raw[record.k0[a]:record.k0[a + 1]].mean(axis=0)
        basis = _plane_basis(f_rest / np.linalg.norm(f_rest))
        Pi, E_tot, Phi = np.eye(3), np.eye(3), np.zeros((3, P))
        for j in range(a + 1, b + 1):
            k = j - 1
            # Pi_j = Pi_{j-1} dR_k: the earlier terms' right perturbations carried through dR_k
            Phi = c.dR[k].T @ Phi + preint.J_dR[k]
            Pi = Pi @ c.dR[k]
            E_tot = E[k] @ E_tot
            T = record.t_key[j] - record.t_key[a]
            s = np.sqrt(sigma**2 + gyro_noise**2 * T)
            key[row] = a
            if j < b:
                m = Ra.T @ E_tot.T @ n_z
                up_j = Pi.T @ m
                r[row, :2] = basis.T @ (up_j - up_a)
                H_R[row, :2] = basis.T @ (Pi.T @ skew(m) - skew(up_a))
                H_x[row, :2] = basis.T @ skew(up_j) @ Phi
                sig[row, :2] = s
            else:
                Q = Ra.T @ E_tot.T @ Ra
                rc = log_so3(Pi.T @ Q)
                r[row] = rc
                H_R[row] = right_jacobian_inv(rc) @ (np.eye(3) - Q.T)
                H_x[row] = -right_jacobian_inv(-rc) @ Phi
                sig[row] = s
            row += 1
    return Residuals(r=r, key=key, H_R=H_R, H_R_next=None, H_x=H_x, sigma=sig)


__all__ = ["KIND", "find_guided_turns", "turn_factors", "DEFAULT_SIGMA", "FACE_TOLERANCE_DEG", "MIN_TURN_DEG",
           "AXIS_TOLERANCE_DEG", "CLOSURE_TOLERANCE_DEG"]
