r"""Residuals in axes that a heading common to every attitude does not turn.

A record without a table holds its heading by the Earth rate alone: turning every keyframe attitude about the
vertical, ``Exp([0, 0, psi]) C_nb``, changes the cost by the Earth rate's small terms only.  A residual written in
level axes turns with that heading, its norm unchanged; Gauss-Newton's curvature along the heading is then the sum
of the squared horizontal whitened residuals, while the cost's own (the second-order terms cancel it) is the Earth
rate's: on a simulated hand-held record with a noisy gyro 317 against 0.30.  Both solvers, Gauss-Newton at heart,
then crept along the heading: steps of a few mrad, hundreds of iterations.

So each factor whose noise is isotropic in the horizontal plane (``sigma = diag(h, h, v)`` in level axes) and whose
residual is written in level axes is given to the solvers whitened and turned into body axes: ``u = s C^T D^{-1/2} r``
with sigma ``s`` on every component, ``C`` an attitude of the factor (its keyframe's start for the gravity factor,
its end ``A = E R_k dR`` for a rotation factor conditioned on it, :mod:`graph_calib.model.gravity_gyro_noise`).  A
common heading ``H`` turns ``r`` into ``H r`` and ``C`` into ``H C``, and ``D`` commutes with ``H``: ``u`` is unchanged.
The components stay independent and of equal variance (an orthogonal map of a whitened vector), so the cost, every
redundancy sum over a factor and every score statistic are those of the level axes.  The Jacobians take the turn of
``C^T``: a right perturbation ``delta`` of ``C`` maps ``C^T v`` to ``C^T v + [C^T v x] delta``.
"""

from __future__ import annotations

import numpy as np

from graph_calib.model.factors import Residuals
from graph_calib.navigation.rotations import skew


def to_body_axes(res, C, *, rows=None, C_jacobians=()):
    """``res`` (level axes, noise ``diag(h, h, v)``) whitened and turned into the axes of ``C`` (module doc).

    Parameters
    ----------
    res : graph_calib.model.factors.Residuals
    C : ndarray, shape (F, 3, 3)
        The attitude ``C_nb`` of each factor of ``rows``.
    rows : ndarray of int, optional
        The factors to turn (default every one).
    C_jacobians : sequence of (name, ndarray (F, 3, n) or None)
        How ``C`` moves with the factor's variables, as right perturbations: ``("H_R", J)``, ``("H_R_next", J)`` or
        ``("H_x", J)``; ``C``'s turn enters that Jacobian as ``[u x] J`` (``J`` None: the identity, ``C`` being that
        variable itself).

    Returns
    -------
    Residuals
        A new object; ``res`` untouched.
    """
    rows = np.arange(res.r.shape[0]) if rows is None else np.asarray(rows)
    if rows.size == 0:
        return res
    sig = res.sigma[rows]
    s = sig[:, 2]
    M = np.swapaxes(C, 1, 2) * (s[:, None] / sig)[:, None, :]          # s C^T D^{-1/2}
    u = np.einsum("fij,fj->fi", M, res.r[rows])
    U = skew(u)
    out = {"H_R": res.H_R.copy(), "H_x": res.H_x.copy(),
           "H_R_next": None if res.H_R_next is None else res.H_R_next.copy()}
    for name in out:
        if out[name] is not None:
            out[name][rows] = M @ getattr(res, name)[rows]
    for name, J in C_jacobians:
        out[name][rows] += U if J is None else U @ J
    r, sigma = res.r.copy(), res.sigma.copy()
    r[rows] = u
    sigma[rows] = s[:, None]
    return Residuals(r=r, key=res.key, H_R=out["H_R"], H_R_next=out["H_R_next"], H_x=out["H_x"], sigma=sigma)


__all__ = ["to_body_axes"]
