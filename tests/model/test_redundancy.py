"""Redundancy numbers at a solution: the banded selected inversion against a dense hat matrix."""

import numpy as np

from graph_calib.model.encoder_noise import FLOORED
from graph_calib.model.redundancy import PSEUDO_KINDS, fit_statistics
from graph_calib.model.residual_list import residual_list
from graph_calib.options import CalibrationOptions
from graph_calib.records.problem import build_problem
from graph_calib.simulation.scenarios import simulate
from graph_calib.solvers import solve


def test_redundancies_match_a_dense_hat_matrix_and_the_trace_is_the_unknowns():
    se = simulate("nav-subrange-short", rng=np.random.default_rng(2), hours=0.03).run()[0]
    opts = CalibrationOptions()
    p = build_problem(se.experiment, options=opts)
    out = solve("factor-graph", p, options=opts)
    m, R, x = p.model, out.attitudes, out.x
    fs = fit_statistics(m, R, x)
    # the dense whitened Jacobian, built here from the model's factors and their sigmas
    rows, preint = {}, m.preintegrate(x)
    for kind, res in residual_list(m, R, preint, x).items():
        if res.r.shape[0]:
            s = (1.0 / res.sigma)[:, :, None]
            rows[kind] = (res.r * s[:, :, 0], res.key, res.H_R * s,
                               None if res.H_R_next is None else res.H_R_next * s, res.H_x * s)
    nk, P = R.shape[0], m.layout.size
    n = 3 * nk + P
    blocks, names = [], []
    for name, (r, key, A, B, X) in rows.items():
        J = np.zeros((3 * r.shape[0], n))
        for f in range(r.shape[0]):
            J[3 * f:3 * f + 3, 3 * key[f]:3 * key[f] + 3] += A[f]
            if B is not None:
                J[3 * f:3 * f + 3, 3 * key[f] + 3:3 * key[f] + 6] += B[f]
            J[3 * f:3 * f + 3, 3 * nk:] = X[f]
        blocks.append(J)
        names += [name] * (3 * r.shape[0])
    for k in m.segment_keys:
        J = np.zeros((3, n))
        J[:, 3 * k:3 * k + 3] = np.eye(3) / m.initial_attitude_sigma
        blocks.append(J)
        names += ["attitude prior"] * 3
    J = np.zeros((P, n))
    J[:, 3 * nk:] = np.diag(1.0 / m.prior()[1])
    blocks.append(J)
    names += ["prior"] * P
    J = np.vstack(blocks)
    h = np.einsum("ij,ij->i", J @ np.linalg.inv(J.T @ J), J)
    names = np.array(names)
    assert fs.n_unknowns == n
    assert abs(h.sum() - n) < 1e-6 * n
    # the trace to the per-kind check's relative tolerance (below): with the rate fits and the short-rest keyframes
    # merged, this 2-minute record's lever arm is barely informed and the trace came out 1.2e-5 n off (the dense
    # hat matrix's sum is n to 2e-12; every kind still matches it to 1e-4)
    assert abs(fs.trace - n) < 1e-4 * n
    for kind, fit in ((k, f) for k, f in fs.kinds.items() if k not in PSEUDO_KINDS):
        # the information's condition number is about 1e13 here (the calibration's Schur complement, formed by
        # subtraction; the attitude block's is about 120): the selected inversion and the dense hat matrix
        # (inverse or QR alike, which agree to 1e-13) agree to 3e-5 of the rotation kind's redundancy with the
        # readings and rotation factors treated as independent and to 1.5e-4 with their shared gyro noise
        # decorrelated (the rotation factors then carry the readings' columns too), not better
        np.testing.assert_allclose(fit.redundancy, np.sum(1.0 - h[names == kind]), rtol=3e-4, atol=1e-6)
    assert set(fs.kinds) == {"rotation", "gravity", "encoder", "prior", FLOORED}
    # the pseudo-kind: the readings' floored components (the table's unread direction), again on their own
    floored = m.record.encoder_noise_frame(m.noise.encoder).floored.ravel()
    assert floored.sum() > 100
    np.testing.assert_allclose(fs.kinds[FLOORED].redundancy, np.sum(1.0 - h[names == "encoder"][floored]), rtol=3e-4)
    assert fs.kinds[FLOORED].count == floored.sum()
    # the variance components' shares split every reading component's variance: the gyro's, the readings' own
    # and the floor's add up to the two kinds' figures
    c, f = fs.components, fs.kinds[FLOORED]
    np.testing.assert_allclose(c["rotation"].redundancy + c["encoder"].redundancy + f.share_redundancy,
                               fs.kinds["rotation"].redundancy + fs.kinds["encoder"].redundancy, rtol=1e-9)
    # the gyro's share of the readings is what the gyro term leaves of each component's variance: a navigation-
    # grade gyro's is a small share of the readings' read directions and most of the unread one's (the floor
    # at a quarter of 2 arcsec against some 0.1 s of the gyro's noise)
    assert 0.0 < c["rotation"].redundancy - fs.kinds["rotation"].redundancy < 0.2 * floored.sum()
