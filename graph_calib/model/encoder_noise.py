r"""The noise of the table readings: its covariance per reading and the frame that whitens it.

A turntable's faceplate attitude ``C_nf`` is computed from its encoders.  A two-axis table has two:
their noise turns the faceplate about the two axes and not about the direction perpendicular to both,
so the reading noise is not isotropic (one direction of the three is read far better than the
declared ``encoder_noise`` says).  The experiment file does not say which axes the table has
(data-format.md), but the readings show it: at rest the faceplate does not move, so the scatter of
a static dwell's readings *is* the reading noise.

Per valid reading the covariance of the attitude noise, in body axes (the encoder residual's frame,
``r ~ r_0 - C_fb^T e_f`` for a faceplate noise ``e_f``), is taken as

1. **a static dwell's scatter** when the reading belongs to a run of at least
   :data:`MIN_DWELL_READINGS` consecutive valid readings taken at rest (the keyframe static, the raw
   rate against the level frame below :attr:`PreparedRecord.LAG_RATE_THRESHOLD`, no gap longer than
   twice the median reading interval): ``S = sum (e_i - e_mean)(e_i - e_mean)^T / (n - 1)`` of
   ``e_i = Log(C_ref^T C_nf_i)`` (``C_ref`` the run's first reading), scaled by
   ``(n - 1) / (n - 5)`` so that its inverse, the weight, is unbiased (Wishart, three dimensions);
   a dwell never spans a segment boundary (``/imu/segment``);
2. **the table's axes**, for the readings of such a dwell, when the experiment carries them
   (:attr:`graph_calib.records.experiment.Table.axes_f`: a bench program simulated without noise for
   ``predict``, which knows its axes and has no scatter to show; never read from a file): the
   declared ``encoder_noise`` squared about each axis;
3. otherwise (readings in motion, short runs, a dwell whose readings scatter less than the floor
   below in every direction: noiseless simulated readings, or encoders quantised coarser than their
   noise, whose error is then constant over the dwell) the declared ``encoder_noise`` squared on all
   three components, as before.

In 1 and 2 each principal variance is floored at ``(FLOOR_FRACTION * encoder_noise)^2``: a
direction in which the readings do not scatter is not known perfectly (a real table's axes wobble and
are not exactly perpendicular: errors constant over a dwell that its scatter cannot show), and no
direction is given more than ``1 / FLOOR_FRACTION^2 = 16`` times the declared weight.  With a quarter
the predicted sigmas of the mount and the misalignments sit within about 5 % of what the floor's
absence would give on a navigation-grade two-axis table (docs/design.md), so the floor costs little
where the table is as modelled and bounds the harm where it is not.

The encoder factor adds the gyro term ``q_g^2 tau`` (isotropic) to each principal variance and
rotates its residual and Jacobians into the principal axes ``U`` (``r' = U^T r``): each component is
then independent with its own sigma (``Residuals.sigma`` stays per component, and every solver
whitens as before).  ``U`` is data only (the record and the declared noise), so the Jacobians are
those of the same residual, rotated.  Its columns are ordered and signed to lie nearest the body
axes ``x, y, z``, so the components still read as body axes in the reports; a reading of case 3 keeps
``U = I`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np

from graph_calib.navigation.rotations import log_so3

#: Fewest consecutive static readings whose scatter is taken as their noise covariance.
MIN_DWELL_READINGS = 20
#: Each principal sigma of a scatter or axes covariance is at least this fraction of the declared noise.
FLOOR_FRACTION = 0.25

#: The variance-factor key (``Noise.variance_factors``) of the floored components alone: it multiplies the floor
#: ``(FLOOR_FRACTION * encoder_noise)^2`` of every component whose variance is the floor (where the ``encoder``
#: factor does not), not the gyro term nor the components a dwell's scatter shows.  Estimated with the other kinds' factors
#: (:mod:`graph_calib.solvers.variance`), so that the direction a table does not read gets the weight its
#: residuals ask for, and the readings' other components and the rotation factors are not rescaled to make up
#: for it (docs/model.md, "The table's unread direction").
FLOORED = "encoder.floored"

_PERMS = np.array(list(permutations(range(3))))


@dataclass(frozen=True)
class DwellScatter:
    """The scatter of the static dwells' readings (data only).

    Attributes
    ----------
    cov_b : ndarray, shape (D, 3, 3)
        Each dwell's scatter covariance in body axes, rad^2.
    size : ndarray of int, shape (D,)
        Readings in each dwell.
    dwell : ndarray of int, shape (M,)
        The dwell of each reading, -1 where none (case 3 of the module docstring).
    """

    cov_b: np.ndarray
    size: np.ndarray
    dwell: np.ndarray

    @property
    def n_dwells(self):
        return int(self.size.size)

    @property
    def n(self):
        """Readings in each reading's dwell, 0 where it is in none, shape (M,)."""
        return np.where(self.dwell >= 0, self.size[np.maximum(self.dwell, 0)] if self.size.size else 0, 0)


def dwell_scatter(t, C_nf, at_rest, *, C_fb, group=None, min_readings=MIN_DWELL_READINGS):
    """Group the valid readings into static dwells and take each dwell's scatter.

    Parameters
    ----------
    t : ndarray, shape (M,)
        Reading times, s, increasing.
    C_nf : ndarray, shape (M, 3, 3)
        Faceplate attitudes.
    at_rest : ndarray of bool, shape (M,)
        Whether each reading was taken at rest.
    C_fb : ndarray, shape (3, 3)
        Nominal mounting (the scatter is turned into body axes with it).
    group : ndarray of int, shape (M,), optional
        A dwell never spans a change of ``group`` (the record's segments).
    min_readings : int
        Fewest readings of a dwell (at least 6: the unbiasing factor needs ``n > 5``).

    Returns
    -------
    DwellScatter
    """
    M = t.size
    dwell = np.full(M, -1, dtype=np.int64)
    none = DwellScatter(cov_b=np.zeros((0, 3, 3)), size=np.zeros(0, dtype=np.int64), dwell=dwell)
    if M < min_readings:
        return none
    gap = np.diff(t)
    max_gap = 2.0 * float(np.median(gap))
    # a new run starts at every reading not at rest, after a long gap, or after a reading not at rest
    brk = np.ones(M, dtype=bool)
    brk[1:] = (gap > max_gap) | ~at_rest[1:] | ~at_rest[:-1]
    if group is not None:
        brk[1:] |= np.diff(group) != 0
    run = np.cumsum(brk) - 1
    starts = np.flatnonzero(brk)
    sizes = np.diff(np.append(starts, M))
    keep_run = (sizes >= min_readings) & at_rest[starts]
    sel = keep_run[run]
    if not np.any(sel):
        return none
    idx = np.flatnonzero(sel)
    r_sel = run[idx]
    e = log_so3(np.swapaxes(C_nf[starts[r_sel]], 1, 2) @ C_nf[idx])        # (m, 3) in f, small
    e = e @ C_fb                                                            # C_fb^T e: body axes
    # per-dwell sums (the selected readings of one run are contiguous)
    bounds = np.flatnonzero(np.diff(r_sel)) + 1
    first = np.concatenate([[0], bounds])
    n = np.diff(np.append(first, idx.size))
    s1 = np.add.reduceat(e, first, axis=0)
    s2 = np.add.reduceat(e[:, :, None] * e[:, None, :], first, axis=0)
    mean = s1 / n[:, None]
    S = (s2 - n[:, None, None] * mean[:, :, None] * mean[:, None, :]) / (n - 1)[:, None, None]
    S *= ((n - 1) / (n - 5))[:, None, None]
    dwell[idx] = np.repeat(np.arange(n.size), n)
    return DwellScatter(cov_b=S, size=n.astype(np.int64), dwell=dwell)


@dataclass(frozen=True)
class NoiseFrame:
    """Principal axes and variances of every reading's noise (the module docstring's cases).

    Attributes
    ----------
    U : ndarray, shape (M, 3, 3)
        Columns: the principal axes in body axes (identity for case 3).
    var : ndarray, shape (M, 3)
        The encoder variance along each column of ``U``, rad^2 (the gyro term not included).
    rotated : ndarray of bool, shape (M,)
        Readings of cases 1 and 2 (the others have ``U = I`` and ``var = encoder_noise^2``).
    floored : ndarray of bool, shape (M, 3)
        Components whose variance is the floor.
    source : ndarray of int8, shape (M,)
        1 scatter, 2 axes, 3 declared.
    """

    U: np.ndarray
    var: np.ndarray
    rotated: np.ndarray
    floored: np.ndarray
    source: np.ndarray


def _principal(S, floor_var):
    """Eigen-decomposition of ``S`` (m, 3, 3), axes ordered and signed nearest the body axes, variances floored."""
    lam, V = np.linalg.eigh(S)
    absV = np.abs(V)
    # the permutation of the eigenvectors that puts the largest total weight on the diagonal
    score = absV[:, np.arange(3)[None, :], _PERMS].sum(axis=2)                 # (m, 6)
    perm = _PERMS[np.argmax(score, axis=1)]                                       # (m, 3)
    V = np.take_along_axis(V, perm[:, None, :], axis=2)
    lam = np.take_along_axis(lam, perm, axis=1)
    sign = np.where(np.diagonal(V, axis1=1, axis2=2) < 0.0, -1.0, 1.0)
    V = V * sign[:, None, :]
    floored = lam < floor_var
    return V, np.maximum(lam, floor_var), floored


def noise_frame(scatter, axes_b, *, encoder_noise, floor_fraction=FLOOR_FRACTION):
    """The :class:`NoiseFrame` of every valid reading.

    Parameters
    ----------
    scatter : DwellScatter
    axes_b : ndarray, shape (M, A, 3), or None
        The table's axes in body axes at each reading, when known (case 2).
    encoder_noise : float
        Declared reading noise, rad (one sigma per axis).
    floor_fraction : float

    Returns
    -------
    NoiseFrame
    """
    s2 = float(encoder_noise) ** 2
    M = scatter.dwell.size
    U = np.broadcast_to(np.eye(3), (M, 3, 3)).copy()
    var = np.full((M, 3), s2)
    floored = np.zeros((M, 3), dtype=bool)
    source = np.full(M, 3, dtype=np.int8)
    rows = np.flatnonzero(scatter.dwell >= 0)     # readings of a static dwell
    floor_var = (floor_fraction * float(encoder_noise)) ** 2
    if axes_b is not None:
        a = axes_b[rows]
        S = s2 * np.einsum("mai,maj->mij", a, a)
        source[rows] = 2
    else:
        # a dwell whose readings scatter less than the floor in every direction shows no noise at all
        # (noiseless simulated readings, or encoders quantised coarser than their noise, whose error is
        # then constant over the dwell): it says nothing about the noise, so the declared noise stands
        shows = np.linalg.eigvalsh(scatter.cov_b)[:, -1] >= floor_var if scatter.n_dwells else np.zeros(0, bool)
        rows = rows[shows[scatter.dwell[rows]]]
        S = scatter.cov_b[scatter.dwell[rows]]
        source[rows] = 1
    if rows.size:
        V, lam, fl = _principal(S, floor_var)
        U[rows], var[rows], floored[rows] = V, lam, fl
    rotated = source < 3
    return NoiseFrame(U=U, var=var, rotated=rotated, floored=floored, source=source)


__all__ = ["MIN_DWELL_READINGS", "FLOOR_FRACTION", "FLOORED", "DwellScatter", "NoiseFrame", "dwell_scatter", "noise_frame"]
