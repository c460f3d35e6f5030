"""GTSAM's own graph of the model: the test oracle of the least-squares core's linearisation.

Built from the model's residual list (:data:`graph_calib.model.residual_list.FACTOR_KINDS`), not copied from
the solvers: every keyframe attitude of every experiment a ``Rot3`` variable, every factor a
``gtsam.CustomFactor`` whose residual and Jacobians are the model's (the calibration Jacobian chained onto
the unknowns ``theta`` through the experiment's column map ``M``), a robust kind's factors under GTSAM's
``noiseModel.Robust`` (one per robust group: an encoder factor holds every reading of its keyframe), the
attitude priors and the unknowns' prior GTSAM's native factors.  GTSAM's error, its linearisation and its
elimination of the whole graph are then what the core's vectorised cost, reduced step and covariance
must equal.
"""

from functools import partial

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

from graph_calib.model.residual_list import FACTOR_KINDS, residual_list

#: Key offset of each experiment's attitudes: ``X(e * STRIDE + k)``.
STRIDE = 10**6


def attitude_key(e, k):
    return X(e * STRIDE + k)


class _Evaluation:
    """One experiment's residual list, evaluated once per call into GTSAM (``reset`` before each call)."""

    def __init__(self, e, c, slices):
        self.e, self.c, self.slices, self.R = e, c, slices, None

    def reset(self):
        self.R = None

    def ensure(self, values):
        if self.R is None:
            n = self.c.model.n_keyframes + 1
            self.R = np.array([values.atRot3(attitude_key(self.e, k)).matrix() for k in range(n)])
            theta = np.concatenate([np.asarray(values.atVector(key), dtype=float) for key in self.c.keys])
            x = theta if self.c.M is None else self.c.M @ theta
            self.factors = residual_list(self.c.model, self.R, self.c.preint, x)

    def theta_blocks(self, Hx, H, first):
        M = np.eye(Hx.shape[1]) if self.c.M is None else self.c.M
        at = 0
        for i, key in enumerate(self.c.keys):
            d = self.slices[key]
            H[first + i] = Hx @ M[:, at:at + d]
            at += d


def _error(ev, name, rows, this, values, H):
    ev.ensure(values)
    f = ev.factors[name]
    if H is not None:
        H[0] = f.H_R[rows].reshape(-1, 3)
        first = 1
        if f.H_R_next is not None:
            H[1] = f.H_R_next[rows].reshape(-1, 3)
            first = 2
        ev.theta_blocks(f.H_x[rows].reshape(-1, f.H_x.shape[2]), H, first)
    return f.r[rows].reshape(-1)


def _noise(sigmas, robust, k):
    base = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float).reshape(-1))
    if robust is None or k is None:
        return base
    est = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy}[robust]
    return gtsam.noiseModel.Robust.Create(est.Create(float(k)), base)


def oracle_graph(experiments, *, theta_keys, theta, prior_mean, prior_sigma, robust=None, robust_k=3.0):
    """GTSAM's graph and values of ``experiments`` (objects with ``model, preint, R, R_prior, keys, M``,
    as :class:`graph_calib.solvers.least_squares.Experiment`) at ``theta``.

    Returns ``(graph, values, evaluations)``; call ``reset()`` on every evaluation before each call into GTSAM.
    """
    slices = dict(theta_keys)
    graph, values, evs = gtsam.NonlinearFactorGraph(), gtsam.Values(), []
    at = 0
    for key, d in theta_keys:
        values.insert(key, np.asarray(theta[at:at + d], dtype=float))
        graph.add(gtsam.PriorFactorVector(key, np.asarray(prior_mean[at:at + d], dtype=float),
                                          gtsam.noiseModel.Diagonal.Sigmas(np.asarray(prior_sigma[at:at + d]))))
        at += d
    for e, c in enumerate(experiments):
        m = c.model
        for k, Rk in enumerate(c.R):
            values.insert(attitude_key(e, k), gtsam.Rot3(Rk))
        for k, Rp in zip(m.segment_keys, np.asarray(c.R_prior, dtype=float).reshape(-1, 3, 3)):
            graph.add(gtsam.PriorFactorRot3(attitude_key(e, int(k)), gtsam.Rot3(Rp),
                                            gtsam.noiseModel.Isotropic.Sigma(3, m.initial_attitude_sigma)))
        ev = _Evaluation(e, c, slices)
        ev.ensure(values)
        evs.append(ev)
        for kind in FACTOR_KINDS:
            f = ev.factors[kind.name]
            if f.r.shape[0] == 0:
                continue
            group, k_rob = kind.robust_groups(f, robust=robust, robust_k=robust_k)
            if kind.per_keyframe:     # one factor per keyframe holding its rows
                bounds = np.flatnonzero(np.diff(f.key)) + 1
                runs = list(zip(np.concatenate([[0], bounds]), np.concatenate([bounds, [f.key.size]])))
            else:
                runs = [(i, i + 1) for i in range(f.key.size)]
            for j, (lo, hi) in enumerate(runs):
                rows = slice(int(lo), int(hi))
                k0 = int(f.key[lo])
                att = [attitude_key(e, k0)] + ([attitude_key(e, k0 + 1)] if f.H_R_next is not None else [])
                thr = None if k_rob is None else (k_rob[j] if np.ndim(k_rob) else k_rob)
                graph.add(gtsam.CustomFactor(_noise(f.sigma[rows], robust, thr), att + list(c.keys),
                                             partial(_error, ev, kind.name, rows)))
    return graph, values, evs


def damped(gfg, keys, dims, lam):
    """``gfg`` with ``sqrt(lam) I`` on every variable ``keys`` (Levenberg-Marquardt's damping)."""
    out = gtsam.GaussianFactorGraph()
    out.push_back(gfg)
    for key, d in zip(keys, dims):
        out.add(gtsam.JacobianFactor(key, np.sqrt(lam) * np.eye(d), np.zeros(d), gtsam.noiseModel.Unit.Create(d)))
    return out


def marginal(gfg, eliminate_keys, keep_keys):
    """The covariance of ``keep_keys`` with ``eliminate_keys`` eliminated by GTSAM (multifrontal)."""
    order = gtsam.Ordering()
    for k in eliminate_keys:
        order.push_back(k)
    _, rest = gfg.eliminatePartialMultifrontal(order)
    keep = gtsam.Ordering()
    for k in keep_keys:
        keep.push_back(k)
    return np.linalg.inv(np.asarray(rest.hessian(keep)[0], dtype=float))
