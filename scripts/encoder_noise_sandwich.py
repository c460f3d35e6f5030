"""How honest are the reported sigmas under the simulator's two-angle encoder noise? A linear (sandwich) check.

``PYTHONPATH=. python scripts/encoder_noise_sandwich.py [--seeds 2000 2001] [--hours 0.25]``

For a seed of the shortened navigation-grade programme (``nav-subrange-short``), the whole linearised
system of the factor graph at the nominal calibration (every factor whitened as the model whitens it,
the priors) gives the model's covariance ``[H^-1]_xx`` (what ``predict`` and the factor graph report).
The estimator's true covariance when the encoder readings carry the simulator's noise, ``sigma_enc``
on the table's outer and inner angles and none about the direction perpendicular to both
(``simulation/turntable.py::encoder_readings``), is the sandwich
``Z^T J^T Sigma_w J Z = [H^-1]_xx + sum_m (J_m Z)^T (Sigma_w,m - I) (J_m Z)`` over the readings
(``Z = H^-1 E_x``, ``Sigma_w,m`` the true covariance of reading ``m``'s whitened residual; the rotation
and gravity factors are taken as modelled).  Prints, per element, true sigma / model sigma: 1 when the
encoder noise model is right, below 1 when it overstates the noise.  No noise is drawn, so the figure
has no Monte Carlo scatter (docs/design.md records it for the model before and after
``graph_calib/model/encoder_noise.py``).
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from graph_calib.calibrate import CalibrationOptions, build_problem
from graph_calib.model.residual_list import residual_list
from graph_calib.navigation.rotations import quat_to_dcm
from graph_calib.simulation import simulate


def _system(model, R, x, q_nb0):
    """Whitened Jacobian of every factor and prior (rows) in the attitudes and the calibration (columns)."""
    K, P = model.n_keyframes, model.layout.size
    na = 3 * (K + 1)
    pre = model.preintegrate(x)
    rows, cols, vals, nrow, enc = [], [], [], 0, None
    for kind, res in residual_list(model, R, pre, x).items():
        s = 1.0 / res.sigma[:, :, None]
        HR, Hx = res.H_R * s, res.H_x * s
        HRn = None if res.H_R_next is None else res.H_R_next * s
        F = HR.shape[0]
        rr = nrow + np.arange(3 * F).reshape(F, 3)
        kc = 3 * res.key[:, None] + np.arange(3)[None, :]
        for Hb, kcols in ((HR, kc), (HRn, kc + 3), (Hx, np.broadcast_to(na + np.arange(P)[None, :], (F, P)))):
            if Hb is None:
                continue
            rows.append(np.repeat(rr[:, :, None], Hb.shape[2], axis=2).ravel())
            cols.append(np.broadcast_to(kcols[:, None, :], Hb.shape).ravel())
            vals.append(Hb.ravel())
        if kind == "encoder":
            enc = (nrow, F, res)
        nrow += 3 * F
    for k, pr in model.attitude_priors(R, R_priors=model.segment_priors(q_nb0)):
        rows.append(nrow + np.repeat(np.arange(3), 3))
        cols.append(np.tile(3 * k + np.arange(3), 3))
        vals.append(pr.H.ravel())
        nrow += 3
    cp = model.calibration_prior(x)
    rows.append(nrow + np.arange(P))
    cols.append(na + np.arange(P))
    vals.append(np.diag(cp.H))
    nrow += P
    J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(nrow, na + P))
    return J, enc, na, P


def sandwich(se):
    """``(names, model sigma (P,), true sigma (P,))`` of one simulated experiment."""
    problem = build_problem(se.experiment, options=CalibrationOptions(t_ref_degC=se.truth.t_ref_degC))
    model = problem.model
    x0 = model.layout.zeros()
    R = model.propagate(quat_to_dcm(problem.q_nb0), model.preintegrate(x0), x0)
    J, (r0, F, res), na, P = _system(model, R, x0, problem.q_nb0)
    E = np.zeros((na + P, P))
    E[na:] = np.eye(P)
    Z = spla.splu((J.T @ J).tocsc()).solve(E)
    cov_model = Z[na:]
    # the simulator's reading noise in body axes: sigma_enc^2 (I - n n^T), n perpendicular to both axes
    lag = float(se.layout.get(se.x, "time_lag.table", np.zeros(1))[0])
    ang, _, _ = se.signals.motion.program.angles(model.record.reading_t - lag)
    b = ang[:, 1]
    n_b = np.column_stack([np.sin(b), np.cos(b), np.zeros_like(b)]) @ se.signals.motion.C_fb
    s_enc = float(se.truth.extra["simulation"]["noise"]["encoder_noise_rad"])
    Sig = (s_enc**2 * (np.eye(3) - n_b[:, :, None] * n_b[:, None, :])
           + (model.noise.gyro**2 * model.record.reading_tau)[:, None, None] * np.eye(3))
    frame = getattr(model.record, "encoder_noise_frame", None)
    if frame is not None:                    # the residual in the noise's principal axes: U^T Sig U
        U = frame(model.noise.encoder).U
        Sig = np.swapaxes(U, 1, 2) @ Sig @ U
    s = res.sigma
    D = Sig / (s[:, :, None] * s[:, None, :]) - np.eye(3)
    JZ = (J[r0:r0 + 3 * F] @ Z).reshape(F, 3, P)
    cov_true = cov_model + np.einsum("fip,fij,fjq->pq", JZ, D, JZ)
    return model.layout.element_names(), np.sqrt(np.diag(cov_model)), np.sqrt(np.diag(cov_true))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[2000])
    p.add_argument("--hours", type=float, default=0.25)
    args = p.parse_args(argv)
    ratios = []
    for seed in args.seeds:
        se = simulate("nav-subrange-short", rng=np.random.default_rng(seed), hours=args.hours,
                      curvature=False).run()[0]
        names, s_model, s_true = sandwich(se)
        ratios.append(s_true / s_model)
    ratios = np.array(ratios)
    print(f"true sigma / model sigma under two-angle encoder noise, seeds {args.seeds}")
    for i, nm in enumerate(names):
        print(f"  {nm:<28}" + " ".join(f"{r:.3f}" for r in ratios[:, i]))
    i, j = np.unravel_index(np.argmin(ratios), ratios.shape)
    print(f"lowest {ratios.min():.3f} ({names[j]}, seed {args.seeds[i]}); highest {ratios.max():.3f}")


if __name__ == "__main__":
    main()
