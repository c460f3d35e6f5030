r"""Rotations: skew matrices, SO(3) exponential and logarithm, quaternions.

Conventions: ``C_ab`` maps frame-``b`` coordinates into ``a``; quaternions are
scalar first ``[w, x, y, z]`` with the Hamilton product, ``q_ab`` matching
``C_ab``.  Every function accepts a single item (shape ``(3,)``, ``(4,)``,
``(3, 3)``) or a stack (shape ``(N, 3)``, ``(N, 4)``, ``(N, 3, 3)``) and returns
the same leading shape.

The ``*_nb`` scalar helpers at the end are numba-compiled so that the per-sample
kernels of :mod:`graph_calib.navigation.strapdown` and :mod:`graph_calib.model` call them.
"""

import numba
import numpy as np

from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

_SMALL = 1e-7


def skew(v):
    """Cross-product matrix ``[v x]``, shape (..., 3, 3), with ``skew(a) @ b == cross(a, b)``."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1] = -v[..., 2]
    S[..., 0, 2] = v[..., 1]
    S[..., 1, 0] = v[..., 2]
    S[..., 1, 2] = -v[..., 0]
    S[..., 2, 0] = -v[..., 1]
    S[..., 2, 1] = v[..., 0]
    return S


def exp_so3(a):
    """Rotation matrix ``Exp(a)`` of rotation vectors ``a`` (rad), shape (..., 3) -> (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    theta2 = np.sum(a * a, axis=-1)[..., None, None]
    theta = np.sqrt(theta2)
    small = theta2 < _SMALL**2
    safe = np.where(small, 1.0, theta)
    A = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    B = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    K = skew(a)
    return np.eye(3) + A * K + B * (K @ K)


def log_so3(C):
    """Rotation vector ``a`` with ``Exp(a) == C``, shape (..., 3, 3) -> (..., 3); angle in [0, pi]."""
    C = np.asarray(C, dtype=float)
    return quat_to_rotvec(dcm_to_quat(C))


def right_jacobian(a):
    """Right Jacobian of SO(3): ``Exp(a + d) ~= Exp(a) @ Exp(Jr(a) @ d)``, shape (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    theta2 = np.sum(a * a, axis=-1)[..., None, None]
    theta = np.sqrt(theta2)
    small = theta2 < 1e-10
    safe = np.where(small, 1.0, theta)
    # 1 - cos(t) = 2 sin^2(t/2): no cancellation for small t (A multiplies [a x], of size t)
    A = np.where(small, 0.5 - theta2 / 24.0, 2.0 * np.sin(0.5 * safe) ** 2 / (safe * safe))
    B = np.where(small, 1.0 / 6.0 - theta2 / 120.0, (safe - np.sin(safe)) / (safe**3))
    K = skew(a)
    return np.eye(3) - A * K + B * (K @ K)


def right_jacobian_inv(a):
    """Inverse of :func:`right_jacobian`, shape (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    theta2 = np.sum(a * a, axis=-1)[..., None, None]
    theta = np.sqrt(theta2)
    small = theta2 < 1e-10
    safe = np.where(small, 1.0, theta)
    c = np.where(
        small,
        1.0 / 12.0 + theta2 / 720.0,
        1.0 / (safe * safe) - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(np.where(small, 1.0, safe))),
    )
    K = skew(a)
    return np.eye(3) + 0.5 * K + c * (K @ K)


def quat_multiply(p, q):
    """Hamilton product ``p * q`` of scalar-first quaternions, shape (..., 4)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def quat_conjugate(q):
    """Conjugate (inverse for unit quaternions), shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_dcm(q):
    """``C_ab`` from unit quaternion ``q_ab`` (scalar first), shape (..., 4) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    C = np.empty(q.shape[:-1] + (3, 3))
    C[..., 0, 0] = 1 - 2 * (y * y + z * z)
    C[..., 0, 1] = 2 * (x * y - w * z)
    C[..., 0, 2] = 2 * (x * z + w * y)
    C[..., 1, 0] = 2 * (x * y + w * z)
    C[..., 1, 1] = 1 - 2 * (x * x + z * z)
    C[..., 1, 2] = 2 * (y * z - w * x)
    C[..., 2, 0] = 2 * (x * z - w * y)
    C[..., 2, 1] = 2 * (y * z + w * x)
    C[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return C


def dcm_to_quat(C):
    """Unit quaternion ``q_ab`` (scalar first, ``w >= 0``) from ``C_ab``, shape (..., 3, 3) -> (..., 4).

    Uses the numerically stable branch selection (largest diagonal element).
    """
    C = np.asarray(C, dtype=float)
    shape = C.shape[:-2]
    C = C.reshape(-1, 3, 3)
    tr = np.trace(C, axis1=1, axis2=2)
    diag = np.stack([C[:, 0, 0], C[:, 1, 1], C[:, 2, 2]], axis=1)
    choice = np.argmax(np.column_stack([tr, diag]), axis=1)
    q = np.empty((C.shape[0], 4))
    # branch 0: trace largest
    i = choice == 0
    s = np.sqrt(1.0 + tr[i]) * 2.0
    q[i, 0] = 0.25 * s
    q[i, 1] = (C[i, 2, 1] - C[i, 1, 2]) / s
    q[i, 2] = (C[i, 0, 2] - C[i, 2, 0]) / s
    q[i, 3] = (C[i, 1, 0] - C[i, 0, 1]) / s
    for k, (a, b, c) in enumerate([(0, 1, 2), (1, 2, 0), (2, 0, 1)], start=1):
        i = choice == k
        s = np.sqrt(1.0 + C[i, a, a] - C[i, b, b] - C[i, c, c]) * 2.0
        q[i, 0] = (C[i, c, b] - C[i, b, c]) / s
        q[i, 1 + a] = 0.25 * s
        q[i, 1 + b] = (C[i, a, b] + C[i, b, a]) / s
        q[i, 1 + c] = (C[i, a, c] + C[i, c, a]) / s
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(shape + (4,))


def rotvec_to_quat(a):
    """Quaternion of rotation vectors, shape (..., 3) -> (..., 4)."""
    a = np.asarray(a, dtype=float)
    theta = np.linalg.norm(a, axis=-1, keepdims=True)
    half = 0.5 * theta
    small = theta < _SMALL
    k = np.where(small, 0.5 - theta**2 / 48.0, np.sin(half) / np.where(small, 1.0, theta))
    return np.concatenate([np.cos(half), k * a], axis=-1)


def quat_to_rotvec(q):
    """Rotation vectors (angle in [0, pi]) of unit quaternions, shape (..., 4) -> (..., 3)."""
    q = np.asarray(q, dtype=float)
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    w = q[..., :1]
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, w)
    small = s < _SMALL
    w_safe = np.where(small, w, 1.0)
    k = np.where(small, 2.0 / w_safe * (1.0 - s**2 / (3.0 * w_safe**2)), angle / np.where(small, 1.0, s))
    return k * v


# ---------------------------------------------------------------------------
# numba scalar helpers for the per-sample kernels (one item at a time)
# ---------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def exp_so3_nb(ax, ay, az, out):
    """Write ``Exp([ax, ay, az])`` into the 3x3 array ``out``."""
    t2 = ax * ax + ay * ay + az * az
    if t2 < 1e-14:
        A = 1.0 - t2 / 6.0
        B = 0.5 - t2 / 24.0
    else:
        t = np.sqrt(t2)
        A = np.sin(t) / t
        B = (1.0 - np.cos(t)) / t2
    out[0, 0] = 1.0 - B * (ay * ay + az * az)
    out[1, 1] = 1.0 - B * (ax * ax + az * az)
    out[2, 2] = 1.0 - B * (ax * ax + ay * ay)
    out[0, 1] = -A * az + B * ax * ay
    out[1, 0] = A * az + B * ax * ay
    out[0, 2] = A * ay + B * ax * az
    out[2, 0] = -A * ay + B * ax * az
    out[1, 2] = -A * ax + B * ay * az
    out[2, 1] = A * ax + B * ay * az


@numba.njit(cache=True, inline="always")
def right_jacobian_nb(ax, ay, az, out):
    """Write the SO(3) right Jacobian of ``[ax, ay, az]`` into ``out``."""
    t2 = ax * ax + ay * ay + az * az
    if t2 < 1e-10:
        A = 0.5 - t2 / 24.0
        B = 1.0 / 6.0 - t2 / 120.0
    else:
        t = np.sqrt(t2)
        A = 2.0 * np.sin(0.5 * t) ** 2 / t2  # = (1 - cos t) / t^2 without cancellation
        B = (t - np.sin(t)) / (t2 * t)
    # I - A K + B K^2
    out[0, 0] = 1.0 - B * (ay * ay + az * az)
    out[1, 1] = 1.0 - B * (ax * ax + az * az)
    out[2, 2] = 1.0 - B * (ax * ax + ay * ay)
    out[0, 1] = A * az + B * ax * ay
    out[1, 0] = -A * az + B * ax * ay
    out[0, 2] = -A * ay + B * ax * az
    out[2, 0] = A * ay + B * ax * az
    out[1, 2] = A * ax + B * ay * az
    out[2, 1] = -A * ax + B * ay * az


@numba.njit(cache=True, inline="always")
def right_jacobian_inv_nb(ax, ay, az, out):
    """Write the inverse of the SO(3) right Jacobian of ``[ax, ay, az]`` into ``out`` (:func:`right_jacobian_inv`)."""
    t2 = ax * ax + ay * ay + az * az
    if t2 < 1e-10:
        c = 1.0 / 12.0 + t2 / 720.0
    else:
        t = np.sqrt(t2)
        c = 1.0 / t2 - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t))
    # I + K / 2 + c K^2
    out[0, 0] = 1.0 - c * (ay * ay + az * az)
    out[1, 1] = 1.0 - c * (ax * ax + az * az)
    out[2, 2] = 1.0 - c * (ax * ax + ay * ay)
    out[0, 1] = -0.5 * az + c * ax * ay
    out[1, 0] = 0.5 * az + c * ax * ay
    out[0, 2] = 0.5 * ay + c * ax * az
    out[2, 0] = -0.5 * ay + c * ax * az
    out[1, 2] = -0.5 * ax + c * ay * az
    out[2, 1] = 0.5 * ax + c * ay * az


@numba.njit(cache=True, inline="always")
def log_so3_nb(C, out):
    """Write ``Log(C)`` of the 3x3 rotation ``C`` into the 3-vector ``out`` (:func:`log_so3`: through the quaternion,
    the branch of the largest of the trace and the diagonal, ``w >= 0``)."""
    tr = C[0, 0] + C[1, 1] + C[2, 2]
    best = tr
    choice = 0
    for k in range(3):
        if C[k, k] > best:
            best = C[k, k]
            choice = k + 1
    q0 = q1 = q2 = q3 = 0.0
    if choice == 0:
        s = np.sqrt(1.0 + tr) * 2.0
        q0 = 0.25 * s
        q1 = (C[2, 1] - C[1, 2]) / s
        q2 = (C[0, 2] - C[2, 0]) / s
        q3 = (C[1, 0] - C[0, 1]) / s
    else:
        a = choice - 1                      # the branch (a, b, c) of dcm_to_quat
        b = (a + 1) % 3
        c = (a + 2) % 3
        s = np.sqrt(1.0 + C[a, a] - C[b, b] - C[c, c]) * 2.0
        q0 = (C[c, b] - C[b, c]) / s
        qa = 0.25 * s
        qb = (C[a, b] + C[b, a]) / s
        qc = (C[a, c] + C[c, a]) / s
        if a == 0:
            q1, q2, q3 = qa, qb, qc
        elif a == 1:
            q1, q2, q3 = qc, qa, qb
        else:
            q1, q2, q3 = qb, qc, qa
    if q0 < 0.0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    n = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    q0, q1, q2, q3 = q0 / n, q1 / n, q2 / n, q3 / n
    s = np.sqrt(q1 * q1 + q2 * q2 + q3 * q3)
    if s < _SMALL:
        k = 2.0 / q0 * (1.0 - s * s / (3.0 * q0 * q0))
    else:
        k = 2.0 * np.arctan2(s, q0) / s
    out[0] = k * q1
    out[1] = k * q2
    out[2] = k * q3


@numba.njit(cache=True, inline="always")
def mat3_mul_nb(A, B, out):
    """Write ``A @ B`` of 3x3 arrays into ``out`` (which must not alias ``A`` or ``B``)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@numba.njit(cache=True, inline="always")
def mat3_tmul_nb(A, B, out):
    """Write ``A^T @ B`` of 3x3 arrays into ``out`` (not aliasing either)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = A[0, i] * B[0, j] + A[1, i] * B[1, j] + A[2, i] * B[2, j]


@numba.njit(cache=True, inline="always")
def mat3_mult_nb(A, B, out):
    """Write ``A @ B^T`` of 3x3 arrays into ``out`` (not aliasing either)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[j, 0] + A[i, 1] * B[j, 1] + A[i, 2] * B[j, 2]
