r"""The closed loop of residual analysis: from the residuals to the missing effect.

``diagnose(experiment, options=...)`` calibrates with the declared model, tests
every further effect of ``model.md`` that the declared model lacks, adds the most
significant one, re-solves and repeats until no candidate is significant.  It
then tests the residuals against generic *drivers* (time, temperature, its rate,
the sign and size of the angular rate, angular acceleration, specific force and
its square): structure that no candidate explains is reported as
``unexplained`` with its signature.  ``docs/diagnosis.md`` gives the statistics
and their thresholds.

The statistic: a score (Lagrange-multiplier) test through the factor graph
----------------------------------------------------------------------------
At the solution ``(R_hat, x_hat)`` of the current model the factors of the
model *extended* by the candidates (same experiment, same reference
temperature, same static mask; every candidate's parameters zero) are
linearised once.  With ``J`` the whitened Jacobian in the keyframe attitudes
``a`` and the calibration ``x``, ``r`` the whitened residuals, the Gauss-Newton
system is ``H = J^T J + priors``, ``g = J^T r``.  The attitudes are eliminated
(block-tridiagonal, sparse LU), leaving the reduced system ``(A, b)`` in the
calibration columns.  For a candidate ``c`` against the current columns
``theta`` (with their priors)

.. math::

    u_c = b_c - A_{c\theta} A_{\theta\theta}^{-1} b_\theta, \qquad
    S_c = A_{cc} - A_{c\theta} A_{\theta\theta}^{-1} A_{\theta c}, \qquad
    T_c = u_c^T S_c^{-1} u_c / s^2,

which is twice the decrease of the cost in one Gauss-Newton step of the
extended model from ``(R_hat, x_hat, 0)`` minus that of the current model (the
parameters already estimated and every attitude move in the same step), i.e.
the score statistic; ``T_c ~ chi^2(dim c)`` under the hypothesis that the
effect is absent (linear-Gaussian model).  ``s^2 = max(1, chi^2 / dof)`` of the
current fit guards against noise densities that are too optimistic (measured
data).  No prior enters ``S_c``: the test is on the data alone.  A direction of
the candidate's parameter space counts only where the data determine it better
than the grade's prior (``lambda(D S_c D) >= 1`` with ``D`` the prior sigmas);
a candidate with no such direction is skipped as not identifiable.

Because every candidate's columns come from one linearisation of the extended
model, the whole catalogue costs one preintegration per round.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import stats

from graph_calib import constants as c
from graph_calib import effects
from graph_calib.options import CalibrationOptions
from graph_calib.problem import build_problem
from graph_calib.rotations import quat_to_dcm
from graph_calib.solvers.registry import solve
from graph_calib.solvers.results import to_result

# ---------------------------------------------------------------------------
# drivers: what could drive a missing effect
# ---------------------------------------------------------------------------

#: Sensor axes a generic driver is placed on (as a bias), in order.
SENSOR_AXES = ("gyro.x", "gyro.y", "gyro.z", "accel.x", "accel.y", "accel.z")

#: Driver groups: name -> one-line meaning (the features, per sample, from the raw signals).
DRIVER_GROUPS = {
    "time": "cubic B-splines over the record (slow change of a bias in time, any shape)",
    "temperature": "dT^3 of the sensor (curvature beyond the dT^2 of the candidates)",
    "rate_sign": "sign of the angular rate about x, y, z (0 below the dead band)",
    "rate_size": "|angular rate| about x, y, z (gyro: the other two axes; |w_i| on gyro i is gyro.scale_asym)",
    "angular_acceleration": "angular acceleration (gyro: about x, y, z; accelerometer i: about axis i only, "
                            "the others are the lever arm and accel.size_effect)",
    "specific_force_sq": "square of the specific force (accelerometer i: along the other two axes; f_i^2 "
                         "is accel.nonlinearity)",
}

#: Signatures the descriptive regressions relate the residuals to (keyframe means; ``keyframe_context``).
REGRESSION_DRIVERS = ("time", "temperature", "temperature_rate", "rate", "rate_size", "rate_sign",
                      "angular_acceleration", "specific_force", "specific_force_sq")

#: Dead band of the rate sign, rad/s (2 deg/s: above the bias of a consumer gyro).
RATE_SIGN_DEADBAND = np.deg2rad(2.0)

#: Number of cubic B-spline functions of the ``time`` driver.
TIME_SEGMENTS = 12


@dataclass(frozen=True)
class Driver:
    """One generic driver column: a bias on ``axis`` that follows ``series`` (per sample)."""

    group: str
    axis: str          # one of SENSOR_AXES
    label: str         # e.g. "f_x", "segment 3"
    series: int        # index into the driver series matrix


def time_basis(t, n):
    """Cubic B-spline basis on uniform knots over the record, shape (N, n), rows summing to one.

    Any slow change in time (a drift, a sinusoid of up to about ``(n - 3) / 2``
    cycles per record) lies nearly in its span; the constant is the bias itself.
    """
    from scipy.interpolate import BSpline

    k = 3
    n = max(int(n), k + 1)
    u = (np.asarray(t, dtype=float) - t[0]) / max(float(t[-1] - t[0]), 1e-12)
    inner = np.linspace(0.0, 1.0, n - k + 1)
    knots = np.concatenate([np.zeros(k), inner, np.ones(k)])
    return BSpline.design_matrix(np.clip(u, 0.0, 1.0), knots, k).toarray()


def driver_series(model, *, n_segments=TIME_SEGMENTS, deadband=RATE_SIGN_DEADBAND):
    """Per-sample driver series of ``model``'s experiment and the driver columns built from them.

    Returns
    -------
    Phi : ndarray, shape (N, D)
        One column per distinct series (SI units; ``dT`` in degC).
    drivers : list of Driver
    """
    e = model.experiment
    w = model.record.w_raw
    f = model.record.f_raw
    dw = model.record.dw_raw
    dT = np.column_stack([model.record.dTg, model.record.dTa])          # (N, 6) per sensor
    cols = []
    names = {}

    def add(key, v):
        names[key] = len(cols)
        cols.append(np.asarray(v, dtype=float))

    for s, col in enumerate(time_basis(e.t, n_segments).T):
        add(("time", s), col)
    for i in range(6):
        add(("dT3", i), dT[:, i] ** 3)
    for j in range(3):
        add(("sign", j), np.sign(w[:, j]) * (np.abs(w[:, j]) > deadband))
        add(("abs", j), np.abs(w[:, j]))
        add(("dw", j), dw[:, j])
        add(("f2", j), f[:, j] ** 2)
    Phi = np.column_stack(cols)
    xyz = "xyz"
    drivers = []
    for i, ax in enumerate(SENSOR_AXES):
        gyro = i < 3
        own = i % 3
        for s in range(n_segments):
            drivers.append(Driver("time", ax, f"B-spline {s + 1}", names[("time", s)]))
        drivers.append(Driver("temperature", ax, "dT^3", names[("dT3", i)]))
        for j in range(3):
            drivers.append(Driver("rate_sign", ax, f"sign(w_{xyz[j]})", names[("sign", j)]))
        for j in range(3):
            if not (gyro and j == own):
                drivers.append(Driver("rate_size", ax, f"|w_{xyz[j]}|", names[("abs", j)]))
        for j in range(3):
            if gyro or j == own:
                drivers.append(Driver("angular_acceleration", ax, f"dw_{xyz[j]}/dt", names[("dw", j)]))
        for j in range(3):
            if gyro or j != own:
                drivers.append(Driver("specific_force_sq", ax, f"f_{xyz[j]}^2", names[("f2", j)]))
    return Phi, drivers


def _cumulative(Phi):
    """Cumulative sums with a leading zero row, for :func:`_interval_means`."""
    Phi = np.asarray(Phi, dtype=float).reshape(Phi.shape[0], -1)
    return np.vstack([np.zeros((1, Phi.shape[1])), np.cumsum(Phi, axis=0)])


def _interval_means(cs, lo, hi):
    """Mean over samples ``[lo, hi)`` of every column, from the cumulative sums ``cs``."""
    cnt = np.maximum(hi - lo, 1)[:, None]
    return (cs[hi] - cs[lo]) / cnt


# ---------------------------------------------------------------------------
# the linearised system with the attitudes eliminated
# ---------------------------------------------------------------------------


@dataclass
class ReducedSystem:
    """Gauss-Newton system in the calibration columns, attitudes eliminated.

    Attributes
    ----------
    columns : list of str
        Flat parameter element names of the extended layout, then ``driver:<i>``.
    A : ndarray (Q, Q)
        Reduced information (data, plus the priors of the ``null`` columns).
    b : ndarray (Q,)
        Reduced gradient ``J^T r`` (plus the prior gradient of the ``null`` columns).
    null : ndarray of int
        Columns of the current model (layout of the solution).
    layout : Layout
        Extended layout (its elements are the first ``layout.size`` columns).
    prior_sigma : ndarray (layout.size,)
    chi2 : float
        Sum of squared whitened data residuals at the solution.
    dof : int
        Scalar data residuals minus the unknowns of the current model.
    residuals : dict
        ``{kind: (r_w (F, 3), key (F,))}`` whitened residuals at the solution.
    """

    columns: list
    A: np.ndarray
    b: np.ndarray
    null: np.ndarray
    layout: object
    prior_sigma: np.ndarray
    chi2: float
    dof: int
    n_drivers: int
    seconds: float = 0.0
    driver_means: np.ndarray | None = None

    @property
    def variance_factor(self):
        return max(1.0, self.chi2 / max(self.dof, 1))


def _add_at(target, keys, values):
    """``target[keys] += values`` for keys in ascending order (duplicates summed)."""
    if keys.size == 0:
        return
    if keys.size == 1 or np.all(keys[1:] > keys[:-1]):
        target[keys] += values
        return
    starts = np.concatenate([[0], np.flatnonzero(np.diff(keys)) + 1])
    target[keys[starts]] += np.add.reduceat(values, starts, axis=0)


def linearise(model, R, x, *, q_nb0, null_names, drivers=True, n_segments=TIME_SEGMENTS, chunk=4096):
    """Linearise ``model`` (an extended layout) at ``(R, x)`` and eliminate the attitudes.

    Parameters
    ----------
    model : CalibrationModel
        Its layout holds the current model's parameters (``null_names``) and the candidates.
    R : ndarray (K+1, 3, 3)
    q_nb0 : ndarray (4,)
        The alignment (prior of the first attitude), as given to the solver.
    x : ndarray (P,)
        The current solution embedded in ``model.layout`` (candidates zero).
    null_names : sequence of str
        Parameters of the current model (their priors enter the system).
    drivers : bool
        Append the generic driver columns.

    Returns
    -------
    ReducedSystem, list of Driver
    """
    t0 = time.perf_counter()
    layout = model.layout
    P = layout.size
    K = model.n_keyframes
    na = 3 * (K + 1)
    pre = model.preintegrate(x)
    kinds = (
        ("rotation", model.rotation_factors(R, pre, x)),
        ("gravity", model.gravity_factors(R, pre, x)),
        ("encoder", model.encoder_factors(R, pre, x)),
    )
    dlist = []
    if drivers:
        Phi, dlist = driver_series(model, n_segments=n_segments)
        Phi_cs = _cumulative(Phi)
        del Phi
        axis_col = {}
        for i, ax in enumerate(SENSOR_AXES):
            triad, el = ax.split(".")
            axis_col[ax] = layout.slice(f"{triad}.bias").start + "xyz".index(el)
        d_bias = np.array([axis_col[d.axis] for d in dlist], dtype=np.int64)
        d_series = np.array([d.series for d in dlist], dtype=np.int64)
    ND = len(dlist)
    Q = P + ND
    # block-tridiagonal attitude information and the coupling to the calibration
    Hdiag = np.zeros((K + 1, 3, 3))
    Hoff = np.zeros((K, 3, 3))            # block (k, k+1)
    Hax = np.zeros((K + 1, 3, Q))
    Hxx = np.zeros((Q, Q))
    ga = np.zeros((K + 1, 3))
    gx = np.zeros(Q)
    chi2 = 0.0
    m_data = 0
    k0 = model.record.k0
    for kind, res in kinds:
        F = res.r.shape[0]
        if F == 0:
            continue
        r, HR, HRn, Hx = res.whitened_system()
        chi2 += float(np.sum(r**2))
        m_data += r.size
        key = res.key
        if drivers:
            lo = k0[key]
            if kind == "encoder":
                hi = model.record.reading_sample + 1
            else:
                hi = k0[key + 1]
        for a in range(0, F, chunk):
            sl = slice(a, min(F, a + chunk))
            X = Hx[sl]
            if drivers:
                means = _interval_means(Phi_cs, lo[sl], hi[sl])          # (f, series)
                XD = X[:, :, d_bias] * means[:, None, d_series]       # (f, 3, ND)
                X = np.concatenate([X, XD], axis=2)
            kk = key[sl]
            A_ = HR[sl]
            rr = r[sl]
            At = np.swapaxes(A_, 1, 2)
            _add_at(Hdiag, kk, At @ A_)
            _add_at(Hax, kk, At @ X)
            _add_at(ga, kk, np.einsum("fji,fj->fi", A_, rr))
            if HRn is not None:
                B_ = HRn[sl]
                Bt = np.swapaxes(B_, 1, 2)
                _add_at(Hdiag, kk + 1, Bt @ B_)
                _add_at(Hoff, kk, At @ B_)
                _add_at(Hax, kk + 1, Bt @ X)
                _add_at(ga, kk + 1, np.einsum("fji,fj->fi", B_, rr))
            Xf = X.reshape(-1, Q)
            Hxx += Xf.T @ Xf
            gx += Xf.T @ rr.reshape(-1)
    # attitude prior on the first keyframe (as factor_graph.build_graph)
    # (the alignment prior: its residual at the solution is part of the current fit)
    # priors of the current model's calibration columns
    cal_prior = model.calibration_prior(x)
    x_sigma = cal_prior.sigma
    null_idx = np.concatenate([np.arange(P)[layout.slice(n)] for n in null_names]).astype(np.int64)
    h = np.diag(cal_prior.H)[null_idx]
    Hxx[null_idx, null_idx] += h**2
    gx[null_idx] += h * cal_prior.r[null_idx]
    att_prior = model.attitude_prior(R[0], R_prior=quat_to_dcm(q_nb0))
    Hdiag[0] += att_prior.H.T @ att_prior.H
    ga[0] += att_prior.H.T @ att_prior.r
    # eliminate the attitudes
    rows, cols, vals = [], [], []
    base = np.arange(3)
    for k in range(K + 1):
        ii = 3 * k + base
        rows.append(np.repeat(ii, 3)), cols.append(np.tile(ii, 3)), vals.append(Hdiag[k].ravel())
    for k in range(K):
        ii = 3 * k + base
        jj = 3 * (k + 1) + base
        rows.append(np.repeat(ii, 3)), cols.append(np.tile(jj, 3)), vals.append(Hoff[k].ravel())
        rows.append(np.repeat(jj, 3)), cols.append(np.tile(ii, 3)), vals.append(Hoff[k].T.ravel())
    Haa = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(na, na))
    lu = spla.splu(Haa)
    rhs = np.concatenate([Hax.reshape(na, Q), ga.reshape(na, 1)], axis=1)
    sol = lu.solve(rhs)
    Hax2 = Hax.reshape(na, Q)
    A = Hxx - Hax2.T @ sol[:, :Q]
    b = gx - Hax2.T @ sol[:, Q]
    A = 0.5 * (A + A.T)
    dof = m_data - na - null_idx.size
    names = layout.element_names() + [f"driver:{i}" for i in range(ND)]
    means = _interval_means(Phi_cs, k0[:-1], k0[1:]) if drivers else None
    rs = ReducedSystem(columns=names, A=A, b=b, null=null_idx, layout=layout, prior_sigma=x_sigma,
                       chi2=chi2, dof=int(dof), n_drivers=ND, seconds=time.perf_counter() - t0,
                       driver_means=means)
    return rs, dlist


# ---------------------------------------------------------------------------
# score statistics
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Score:
    """A score test of some columns against a base set.

    Attributes
    ----------
    statistic : float
        ``u^T S^+ u / s^2`` on the identifiable directions.
    dof : int
        Identifiable directions.
    dim : int
        Columns tested.
    estimate, sigma : ndarray (dim,)
        One-step estimate ``-S^+ u`` (on the identifiable directions) and its sigma
        from every direction (very large where a direction is not identifiable), SI.
    sigma_identifiable : ndarray (dim,)
        The sigma from the identifiable directions only (the spread of ``estimate``).
    """

    statistic: float
    dof: int
    dim: int
    estimate: np.ndarray
    sigma: np.ndarray
    sigma_identifiable: np.ndarray = None

    def p_value(self):
        return float(stats.chi2.sf(self.statistic, self.dof)) if self.dof else 1.0

    def log10_p(self):
        """``log10`` of the p-value (finite far into the tail, where the p-value underflows)."""
        return log10_chi2_sf(self.statistic, self.dof)


def log10_chi2_sf(T, k):
    """``log10 P(chi^2_k > T)``; for huge ``T`` the leading term of the asymptotic series."""
    if k <= 0:
        return 0.0
    v = stats.chi2.logsf(T, k)
    if np.isfinite(v):
        return float(v / np.log(10.0))
    from scipy.special import gammaln

    a, z = 0.5 * k, 0.5 * T
    return float(((a - 1.0) * np.log(z) - z - gammaln(a)) / np.log(10.0))


def score_test(A, b, base, test, *, scale=None, min_eig=1e-3, scale_factor=1.0):
    """Score test of columns ``test`` given columns ``base`` in a reduced system ``(A, b)``.

    Parameters
    ----------
    A, b : ndarray (Q, Q), (Q,)
        Reduced information and gradient (:class:`ReducedSystem`), with the priors of the
        ``base`` columns that have one.
    base, test : ndarray of int
        Column indices (``base`` normally ``rs.null`` plus already accepted columns).
    scale : ndarray (len(test),), optional
        Column scales: a direction counts when ``lambda(D S D) >= min_eig`` with ``D = diag(scale)``.
        Default: ``1 / sqrt(diag(A_tt))`` (the fraction of a column's information left
        after the base, ``min_eig`` relative).
    scale_factor : float
        Variance factor ``s^2`` dividing the statistic.
    """
    base = np.asarray(base, dtype=np.int64)
    test = np.asarray(test, dtype=np.int64)
    Abb = A[np.ix_(base, base)]
    Abt = A[np.ix_(base, test)]
    Att = A[np.ix_(test, test)]
    # the base block may be singular along directions without a prior (drivers in the base)
    cb = sla.cho_factor(Abb + 1e-12 * np.diag(np.diag(Abb)) + 1e-300 * np.eye(base.size), lower=True)
    W = sla.cho_solve(cb, np.column_stack([Abt, b[base]]))
    S = Att - Abt.T @ W[:, :-1]
    u = b[test] - Abt.T @ W[:, -1]
    S = 0.5 * (S + S.T)
    if scale is None:
        d = np.diag(Att)
        scale = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 0.0)
    D = np.asarray(scale, dtype=float)
    lam, V = np.linalg.eigh(D[:, None] * S * D[None, :])
    keep = lam >= min_eig
    du = D * u
    proj = V[:, keep].T @ du
    T = float(np.sum(proj**2 / lam[keep])) / scale_factor
    # one-step estimate and sigma on the identifiable subspace
    Sinv = (V[:, keep] / lam[keep]) @ V[:, keep].T
    est = -D * (Sinv @ du)
    # sigma from every direction: a direction the data do not determine makes it (nearly) infinite
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        inv_lam = np.where(lam > 0, 1.0 / np.where(lam > 0, lam, 1.0), np.inf)
        contrib = np.where(V**2 > 0, V**2 * inv_lam[None, :], 0.0)
        var = D**2 * np.sum(contrib, axis=1) * scale_factor
        var = np.where(np.isnan(var), np.inf, var)
    sig = np.where(np.isfinite(var) & (var > 0), np.sqrt(np.where(np.isfinite(var), var, 0.0)), np.inf)
    sig_id = np.sqrt(D**2 * np.diag(Sinv) * scale_factor)
    return Score(statistic=T, dof=int(np.count_nonzero(keep)), dim=int(test.size), estimate=est, sigma=sig,
                 sigma_identifiable=sig_id)


def _with_priors(rs, cols):
    """A copy of ``rs.A`` with the prior information of calibration columns ``cols`` added."""
    A = rs.A.copy()
    cols = np.asarray([c for c in cols if c < rs.layout.size], dtype=np.int64)
    if cols.size:
        A[cols, cols] += 1.0 / rs.prior_sigma[cols] ** 2
    return A


# ---------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class DiagnosisOptions:
    """How the loop decides.

    Attributes
    ----------
    alpha : float
        False-alarm probability of each decision (family-wise over the tests of
        one decision, Bonferroni): adding any effect to a correct model, or
        calling the residuals structured.  Each of the ``m`` candidate tests of
        a round is run at ``alpha / m``, each of the driver tests at
        ``alpha / m_drivers``.
    identifiable : float
        A candidate's direction counts when the data determine it at least this
        many times better in information than its prior (``lambda(D S D) >= identifiable``).
    driver_min_eig : float
        A driver direction counts when this fraction of its column's information is
        not already explained by the current model.
    max_added : int
        Most effects added.
    candidates : tuple of str or None
        Effects to test (default every further effect of model.md).
    solvers : tuple of str
        Solvers run before and after (``"factor-graph"`` always; ``"sqrt-kf"`` optional).
    encompassing : bool
        Check each accepted candidate against the generic drivers (a candidate that only
        mimics a driver signature the catalogue lacks is not added).
    time_segments : int
        Cubic B-spline functions of the ``time`` driver.
    """

    alpha: float = 0.01
    identifiable: float = 1.0
    driver_min_eig: float = 1e-3
    max_added: int = 4
    candidates: tuple | None = None
    solvers: tuple = ("factor-graph", "sqrt-kf")
    encompassing: bool = True
    time_segments: int = TIME_SEGMENTS


@dataclass(frozen=True)
class CandidateTest:
    """The score test of one further effect in one round."""

    name: str
    statistic: float
    dof: int
    dim: int
    threshold: float
    log10_p: float
    significant: bool
    skipped: str | None
    estimate: tuple
    sigma: tuple

    def to_json(self):
        s = effects.effect(self.name)
        d = {"name": self.name, "statistic": self.statistic, "dof": self.dof, "dim": self.dim,
             "threshold": self.threshold, "log10_p": self.log10_p, "significant": self.significant}
        if self.skipped:
            d["skipped"] = self.skipped
        else:
            d["estimate"] = dict(zip(s.element_names(), self.estimate))
            d["sigma"] = dict(zip(s.element_names(), self.sigma))
            d["report_unit"] = s.report_unit
        return d


@dataclass(frozen=True)
class DriverTest:
    """The score test of one generic driver group placed as a bias on one sensor axis."""

    group: str
    axis: str
    labels: tuple
    statistic: float
    dof: int
    threshold: float
    log10_p: float
    significant: bool
    estimate: tuple
    sigma: tuple
    amplitude: float = 0.0
    profile: tuple = ()      # fitted bias per keyframe, mean removed (NaN where such a bias is not seen)

    @property
    def unit(self):
        return "rad/s" if self.axis.startswith("gyro") else "m/s^2"

    @property
    def report(self):
        """``(unit, factor)`` for reports: deg/h for gyros, micro-g for accelerometers."""
        return ("deg/h", c.RS_TO_DH) if self.axis.startswith("gyro") else ("micro-g", c.MPS2_TO_UG)

    def strength(self):
        """``sqrt(statistic)``: the signature's size in sigmas of its own noise."""
        return float(np.sqrt(max(self.statistic, 0.0)))

    def to_json(self):
        unit, k = self.report
        return {"driver": self.group, "axis": self.axis, "meaning": DRIVER_GROUPS.get(self.group, ""),
                "statistic": self.statistic, "dof": self.dof,
                "threshold": self.threshold, "log10_p": self.log10_p, "significant": self.significant,
                "strength_sigma": self.strength(),
                "amplitude": {"rms": self.amplitude, "unit": self.unit, "rms_report": self.amplitude * k,
                              "report_unit": unit},
                "coefficients": [{"feature": lb, "value": e, "sigma": s if np.isfinite(s) else None,
                                  "unit": f"{self.unit} per unit of the feature"}
                                 for lb, e, s in zip(self.labels, self.estimate, self.sigma)]}


@dataclass
class Round:
    """One round of the loop: the tests at the current model's solution and what was decided."""

    index: int
    layout: tuple
    candidates: list
    drivers: list
    variance_factor: float
    chi2_per_dof: float
    added: str | None = None
    decision: str = ""
    checks: list = field(default_factory=list)
    seconds: float = 0.0

    def to_json(self):
        tested = [c for c in self.candidates if not c.skipped]
        return {
            "round": self.index, "model": list(self.layout), "chi2_per_dof": self.chi2_per_dof,
            "variance_factor": self.variance_factor, "added": self.added, "decision": self.decision,
            "candidates": [c.to_json() for c in sorted(tested, key=lambda c: c.log10_p)]
            + [c.to_json() for c in self.candidates if c.skipped],
            "drivers_significant": [d.to_json() for d in sorted(self.drivers, key=lambda d: d.log10_p)
                                    if d.significant],
            "encompassing_checks": self.checks, "seconds": self.seconds,
        }


@dataclass
class Stage:
    """A calibrated model (before: declared; after: with the added effects).

    Attributes
    ----------
    layout : tuple of str
    problem : graph_calib.problem.Problem
    graph : graph_calib.solvers.interface.SolverOutput
        The factor graph's output.
    results : dict
        ``{solver: Result}``.
    kf : graph_calib.solvers.interface.SolverOutput or None
        The filter's output.
    residuals : dict
        Per factor kind: ``t``, ``key``, ``r`` (SI), ``w`` (whitened; gravity also in body axes).
    innovations : dict
        Filter innovations per kind (``t``, ``w`` (F, 3)); empty without the filter.
    statistics : dict
        :func:`residual_statistics` of both solvers.
    """

    layout: tuple
    problem: object
    graph: object
    results: dict
    kf: object = None
    residuals: dict = field(default_factory=dict)
    innovations: dict = field(default_factory=dict)
    statistics: dict = field(default_factory=dict)
    error: dict | None = None


@dataclass
class Diagnosis:
    """What :func:`diagnose` found (``to_json`` gives ``diagnosis.json``)."""

    source: str
    added: list
    unexplained: bool
    signature: list
    rounds: list
    before: Stage
    after: Stage
    options: DiagnosisOptions
    context: dict
    seconds: float = 0.0

    def to_json(self):
        def stage(s):
            out = {"model": list(s.layout), "residual_rms": residual_rms(s), "residuals": s.statistics}
            if s.error is not None:
                out["error_vs_truth"] = s.error
            return out

        last = self.rounds[-1] if self.rounds else None
        return _finite({
            "format": "imu-calibration-diagnosis",
            "version": 1,
            "source": self.source,
            "added": list(self.added),
            "unexplained": bool(self.unexplained),
            "signature": [d.to_json() for d in self.signature],
            "before": stage(self.before),
            "after": stage(self.after),
            "test": {
                "statistic": "score (Lagrange multiplier) test through the factor graph, chi-square under "
                             "the null; Bonferroni over the candidates of a round",
                "alpha": self.options.alpha,
                "identifiable_information_ratio": self.options.identifiable,
                "driver_tests": "the same score test of generic drivers placed as a bias on each sensor axis",
                "n_candidates_last_round": sum(1 for c in last.candidates if not c.skipped) if last else 0,
                "n_driver_tests": len(last.drivers) if last else 0,
            },
            "rounds": [r.to_json() for r in self.rounds],
            "context": self.context,
            "seconds": self.seconds,
        })


def _finite(obj):
    """``obj`` with every non-finite float replaced by None (JSON has no NaN or infinity)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, (float, np.floating)) and not np.isfinite(obj):
        return None
    return obj


def residual_rms(stage):
    """``{solver: {kind: [rms of the whitened residuals per component]}}`` plus SI figures."""
    out = {}
    if stage.residuals:
        fg = {k: np.sqrt(np.mean(v["w"] ** 2, axis=0)).tolist() for k, v in stage.residuals.items()
              if v["w"].size}
        fg["overall"] = float(np.sqrt(np.mean(np.concatenate([v["w"].ravel() for v in stage.residuals.values()])
                                              ** 2)))
        si = {}
        for k, v in stage.residuals.items():
            if v["r"].size:
                unit = "m/s^2" if k == "gravity" else "rad"
                sel = v.get("static")
                r = v["r"] if sel is None else v["r"][sel]
                si[k] = {"rms": np.sqrt(np.mean(r**2, axis=0)).tolist(), "unit": unit}
        fg["si"] = si
        out["factor-graph"] = fg
    if stage.innovations:
        kf = {k: np.sqrt(np.mean(v["w"] ** 2, axis=0)).tolist() for k, v in stage.innovations.items()}
        kf["overall"] = float(np.sqrt(np.mean(np.concatenate([v["w"].ravel() for v in stage.innovations.values()])
                                              ** 2)))
        out["sqrt-kf"] = kf
    return out


# ---------------------------------------------------------------------------
# residual series and their statistics
# ---------------------------------------------------------------------------


def _factor_residuals(model, R, x):
    """Per kind: time, keyframe, SI and whitened residuals at ``(R, x)``; gravity also in body axes."""
    pre = model.preintegrate(x)
    out = {}
    for kind, res, t in (("rotation", model.rotation_factors(R, pre, x), model.t_key[1:]),
                         ("gravity", model.gravity_factors(R, pre, x), model.t_key[:-1]),
                         ("encoder", model.encoder_factors(R, pre, x), model.record.reading_t)):
        w = res.whitened()
        d = {"t": np.asarray(t, dtype=float), "key": res.key.copy(), "r": res.r.copy(), "w": w}
        if kind == "gravity":
            Rk = R[: model.n_keyframes]
            r_b = np.einsum("kji,kj->ki", Rk, res.r)
            sig_v = res.sigma[:, 2] if res.sigma.ndim == 2 else np.sqrt(res.sigma[:, 2, 2])
            d["r_body"] = r_b
            d["w_body"] = r_b / sig_v[:, None]
            d["static"] = model.record.static_key.copy()
        out[kind] = d
    return out


def _innovations(output, model):
    """Filter innovations per kind as ``{"t", "key", "w" (F, 3)}`` from the filter's :class:`SolverOutput`."""
    out = {}
    for name, series in output.residuals.items():
        tt = np.asarray(series.t, dtype=float)
        key = np.clip(np.searchsorted(model.t_key, tt, side="right") - 1, 0, model.n_keyframes - 1)
        out[name] = {"t": tt, "key": key, "w": np.asarray(series.values)}
    return out


def ljung_box(y, lags=10):
    """Ljung-Box statistic of ``y`` (columns separately) and its chi-square p-values."""
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    n = y.shape[0]
    h = int(min(lags, max(1, n // 5)))
    if n < 10:
        return np.zeros(y.shape[1]), np.ones(y.shape[1]), h
    yc = y - y.mean(axis=0)
    den = np.sum(yc**2, axis=0)
    den = np.where(den > 0, den, 1.0)
    Q = np.zeros(y.shape[1])
    for k in range(1, h + 1):
        rho = np.sum(yc[k:] * yc[:-k], axis=0) / den
        Q += rho**2 / (n - k)
    Q *= n * (n + 2)
    return Q, stats.chi2.sf(Q, h), h


def keyframe_context(model):
    """Keyframe means of the drivers, for regressions and figures: ``{name: (K, ...)}``."""
    k0 = model.record.k0
    lo, hi = k0[:-1], k0[1:]

    def mean(a):
        a = np.asarray(a, dtype=float)
        return _interval_means(_cumulative(a), lo, hi).reshape((lo.size,) + a.shape[1:])

    t = model.experiment.t
    dT = np.column_stack([model.record.dTg, model.record.dTa])
    dTdt = np.column_stack([model.record.dTdtg, model.record.dTdta])
    w = model.record.w_raw
    return {
        "time": mean(t - t[0]),
        "temperature": mean(dT),
        "temperature_rate": mean(dTdt),
        "rate": mean(w),
        "rate_size": mean(np.abs(w)),
        "rate_sign": mean(np.sign(w) * (np.abs(w) > RATE_SIGN_DEADBAND)),
        "angular_acceleration": mean(model.record.dw_raw),
        "specific_force": mean(model.record.f_raw),
        "specific_force_sq": mean(model.record.f_raw**2),
    }


def _regressors(ctx, group, key):
    c = ctx[group][key]
    if group == "time":
        u = c / max(float(np.max(ctx["time"])), 1e-9)
        return np.column_stack([u, u**2, u**3])
    if group == "temperature":
        m = c.mean(axis=1)
        return np.column_stack([m, m**2])
    if group == "temperature_rate":
        return c.mean(axis=1)[:, None]
    return c.reshape(c.shape[0], -1)


def regression_tests(series, ctx, *, key, static=None):
    """F-tests of each component of ``series`` (F, 3) on each driver group's keyframe means.

    Descriptive: successive residuals are not independent, so the p-values are
    optimistic; the loop decides with the score tests, not with these.

    Returns
    -------
    list of dict
        ``{"driver", "component", "F", "df", "log10_p", "r2"}`` sorted by ``log10_p``.
    """
    out = []
    y_all = np.asarray(series, dtype=float)
    sel = np.ones(y_all.shape[0], dtype=bool) if static is None else np.asarray(static, dtype=bool)
    y_all = y_all[sel]
    key = np.asarray(key)[sel]
    n = y_all.shape[0]
    if n < 20:
        return out
    for group in ctx:
        X = _regressors(ctx, group, key)
        X = X[:, np.std(X, axis=0) > 0]
        if X.shape[1] == 0:
            continue
        Xc = np.column_stack([np.ones(n), X])
        q = X.shape[1]
        for comp in range(y_all.shape[1]):
            y = y_all[:, comp]
            coef, *_ = np.linalg.lstsq(Xc, y, rcond=None)
            rss1 = float(np.sum((y - Xc @ coef) ** 2))
            rss0 = float(np.sum((y - y.mean()) ** 2))
            if rss0 <= 0 or n - q - 1 <= 0:
                continue
            F = ((rss0 - rss1) / q) / max(rss1 / (n - q - 1), 1e-300)
            lp = stats.f.logsf(F, q, n - q - 1) / np.log(10.0)
            out.append({"driver": group, "component": comp, "F": float(F), "df": [q, n - q - 1],
                        "log10_p": float(lp) if np.isfinite(lp) else -300.0, "r2": 1.0 - rss1 / rss0})
    out.sort(key=lambda d: d["log10_p"])
    return out


_COMPONENTS = {"rotation": "xyz (body)", "gravity": "ENU", "gravity_body": "xyz (body)", "encoder": "xyz (body)"}


def residual_statistics(stage, *, top=5, lags=10):
    """Whiteness and driver relations of the residuals of both solvers.

    Returns
    -------
    dict
        ``{solver: {series: {"count", "components", "rms", "ljung_box": {"lags", "Q", "p"},
        "drivers": [top driver regressions]}}}``.
    """
    model = stage.problem.model
    ctx = keyframe_context(model)
    out = {}

    def one(w, key, components, static=None):
        Q, p, h = ljung_box(w, lags)
        return {"count": int(w.shape[0]), "components": components,
                "rms": np.sqrt(np.mean(w**2, axis=0)).tolist(),
                "ljung_box": {"lags": h, "Q": Q.tolist(), "p": p.tolist()},
                "drivers": regression_tests(w, ctx, key=key, static=static)[:top]}

    fg = {}
    for kind, d in stage.residuals.items():
        if d["w"].shape[0] == 0:
            continue
        fg[kind] = one(d["w"], d["key"], _COMPONENTS[kind])
        if kind == "gravity":
            fg["gravity_body"] = one(d["w_body"], d["key"], _COMPONENTS["gravity_body"], static=d["static"])
    out["factor-graph"] = fg
    if stage.innovations:
        kf = {}
        for kind, d in stage.innovations.items():
            kf[kind] = one(d["w"], d["key"], _COMPONENTS[kind])
        out["sqrt-kf"] = kf
    return out


# ---------------------------------------------------------------------------
# error against a truth
# ---------------------------------------------------------------------------


def error_against_truth(result, truth, *, names=None, sigmas=None):
    """Error of ``result`` against a truth :class:`~graph_calib.experiment.Result`.

    Over the declared parameters both hold (or ``names``): per element
    ``z = (estimate - truth) / sigma`` (the result's own sigma, or ``sigmas``: e.g. the
    declared model's, to compare two results on one scale) and the error in prior
    sigmas of the result's grade.

    Returns
    -------
    dict
        ``rms_z``, ``max_abs_z`` and ``worst`` (element), ``rms_prior`` (error in prior
        sigmas, RMS), ``groups`` ``{parameter: {"rms_z", "rms_abs", "report_unit"}}``.
    """
    names = effects.DECLARED if names is None else names
    sigmas = result.sigmas if sigmas is None else sigmas
    priors = result.extra.get("priors", {}) if result.extra else {}
    z, zp, groups = [], [], {}
    worst, wz = None, 0.0
    for n in names:
        spec = effects.effect(n)
        els = [e for e in spec.element_names() if e in result.values and e in truth.values]
        if not els:
            continue
        err = np.array([result.values[e] - truth.values[e] for e in els])
        sig = np.array([sigmas[e] for e in els])
        zz = err / np.where(sig > 0, sig, np.inf)
        z.extend(zz.tolist())
        if n in priors:
            ps = np.atleast_1d(np.asarray(priors[n], dtype=float))
            ps = np.broadcast_to(ps, err.shape) if ps.size in (1, err.size) else np.full(err.shape, np.nan)
            zp.extend((err / ps).tolist())
        groups[n] = {"rms_z": float(np.sqrt(np.mean(zz**2))),
                     "rms_abs": float(np.sqrt(np.mean(err**2)) * spec.to_report),
                     "report_unit": spec.report_unit}
        i = int(np.argmax(np.abs(zz)))
        if abs(zz[i]) > wz:
            wz, worst = float(abs(zz[i])), els[i]
    z = np.asarray(z)
    zp = np.asarray(zp)
    return {"rms_z": float(np.sqrt(np.mean(z**2))) if z.size else 0.0, "max_abs_z": wz, "worst": worst,
            "rms_prior": float(np.sqrt(np.nanmean(zp**2))) if zp.size else None, "n": int(z.size),
            "groups": groups}


# ---------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------

def _columns(layout, name):
    return np.arange(layout.size)[layout.slice(name)]


def _with_effects(options, effects):
    return replace(options, model=replace(options.model, extra_effects=tuple(effects)))


def _solve(problem, options, initial=None):
    return solve("factor-graph", problem, options=options, initial=initial)


def _make_stage(problem, gr, options, dopt, *, truth=None, fixed_sigmas=None, say=lambda m: None):
    model = problem.model
    series = _factor_residuals(model, gr.attitudes, gr.x)
    results = {"factor-graph": to_result(model, gr)}
    st = Stage(layout=tuple(model.layout.names), problem=problem, graph=gr, results=results, residuals=series)
    if "sqrt-kf" in dopt.solvers:
        say("  square-root filter ...")
        kf = solve("sqrt-kf", problem, options=options)
        st.results["sqrt-kf"] = to_result(model, kf)
        st.kf = kf
        st.innovations = _innovations(kf, model)
    st.statistics = residual_statistics(st)
    if truth is not None:
        st.error = {}
        for solver, res in st.results.items():
            e = error_against_truth(res, truth)
            if fixed_sigmas is not None and solver in fixed_sigmas:
                e["rms_z_fixed"] = error_against_truth(res, truth, sigmas=fixed_sigmas[solver])["rms_z"]
            else:
                e["rms_z_fixed"] = e["rms_z"]
            st.error[solver] = e
    return st


def _added_text(t, why=""):
    """The round's decision when candidate test ``t`` is added (``why``: what the encompassing test said)."""
    return (f"added {t.name}: score statistic {t.statistic:.1f} > {t.threshold:.1f} "
            f"(chi-square, {t.dof} dof, log10 p = {t.log10_p:.1f})" + (f"; {why}" if why else ""))


def _round(index, experiment, options, problem, gr, dopt, candidates, *, allow_add=True, say=lambda m: None):
    """One round: linearise the extended model at the solution, test, decide."""
    t0 = time.perf_counter()
    model = problem.model
    cand = [c for c in candidates if c not in model.layout]
    # the same prepared record, static intervals and alignment: only the layout grows
    ext = model.with_effects(tuple(options.model.extra_effects) + tuple(cand))
    x_ext = ext.layout.embed(model.layout, gr.x)
    rs, dlist = linearise(ext, gr.attitudes, x_ext, q_nb0=problem.q_nb0, null_names=model.layout.names,
                          n_segments=dopt.time_segments)
    vf = rs.variance_factor
    A, b = rs.A, rs.b
    # candidates
    raw = {}
    skipped = {}
    for c in cand:
        if c not in ext.layout:
            skipped[c] = effects.effect(c).why_needs or "not estimable in this experiment's model"
            continue
        idx = _columns(ext.layout, c)
        sc = score_test(A, b, rs.null, idx, scale=rs.prior_sigma[idx], min_eig=dopt.identifiable, scale_factor=vf)
        if sc.dof == 0:
            skipped[c] = ("not identifiable: the data determine no combination of its elements better than "
                          "the prior")
            continue
        raw[c] = (idx, sc)
    m = max(1, len(raw))
    tests = []
    for c in cand:
        if c in skipped:
            tests.append(CandidateTest(c, 0.0, 0, effects.effect(c).size, float("nan"), 0.0, False, skipped[c],
                                       (), ()))
            continue
        idx, sc = raw[c]
        thr = float(stats.chi2.isf(dopt.alpha / m, sc.dof))
        tests.append(CandidateTest(c, sc.statistic, sc.dof, sc.dim, thr, sc.log10_p(), sc.statistic > thr, None,
                                   tuple(sc.estimate.tolist()), tuple(sc.sigma.tolist())))
    # drivers
    groups = {}
    for i, d in enumerate(dlist):
        groups.setdefault((d.group, d.axis), []).append(i)
    draw = {}
    for key, ii in groups.items():
        idx = rs.layout.size + np.asarray(ii)
        sc = score_test(A, b, rs.null, idx, min_eig=dopt.driver_min_eig, scale_factor=vf)
        if sc.dof:
            draw[key] = (idx, ii, sc)
    md = max(1, len(draw))
    dtests = []
    dthr = {}
    # where an accelerometer bias is seen: every keyframe, or only the static ones without a table
    acc_keys = ext.record.static_key if ext.options.moving_sigma is not None else np.ones(ext.n_keyframes, bool)
    for (g, ax), (idx, ii, sc) in draw.items():
        thr = float(stats.chi2.isf(dopt.alpha / md, sc.dof))
        dthr[(g, ax)] = thr
        prof = rs.driver_means[:, [dlist[i].series for i in ii]] @ sc.estimate     # fitted bias per keyframe
        seen = acc_keys if ax.startswith("accel") and np.any(acc_keys) else np.ones(prof.size, bool)
        prof = np.where(seen, prof - prof[seen].mean(), np.nan)                   # the mean is the bias
        dtests.append(DriverTest(g, ax, tuple(dlist[i].label for i in ii), sc.statistic, sc.dof, thr,
                                 sc.log10_p(), sc.statistic > thr, tuple(sc.estimate.tolist()),
                                 tuple(sc.sigma_identifiable.tolist()), float(np.sqrt(np.nanmean(prof**2))),
                                 tuple(prof.tolist())))
    rnd = Round(index=index, layout=tuple(model.layout.names), candidates=tests, drivers=dtests,
                variance_factor=vf, chi2_per_dof=rs.chi2 / max(rs.dof, 1))
    significant = sorted((t for t in tests if t.significant), key=lambda t: t.log10_p)
    sig_drivers = [d for d in dtests if d.significant]
    if not significant:
        rnd.decision = (f"no candidate significant at alpha = {dopt.alpha:g} "
                        f"(Bonferroni over {len(raw)} candidates)")
    elif not allow_add:
        rnd.decision = f"most significant candidate {significant[0].name} not added: the limit of added effects"
    for t in significant if allow_add else ():
        idx = raw[t.name][0]
        if not dopt.encompassing or not sig_drivers:
            rnd.added, rnd.decision = t.name, _added_text(t)
            break
        # encompassing: does the candidate explain the driver signatures, or only mimic one?
        A_c = _with_priors(rs, idx)
        base_c = np.concatenate([rs.null, idx])
        left = []
        for d in sig_drivers:
            didx = draw[(d.group, d.axis)][0]
            sc = score_test(A_c, b, base_c, didx, min_eig=dopt.driver_min_eig, scale_factor=vf)
            if sc.statistic > d.threshold and sc.dof:
                left.append((sc.log10_p(), d, didx, sc))
        check = {"candidate": t.name, "drivers_significant_before": len(sig_drivers),
                 "drivers_left_given_candidate": [{"driver": d.group, "axis": d.axis, "statistic": sc.statistic,
                                                   "dof": sc.dof, "threshold": d.threshold}
                                                  for _, d, _, sc in sorted(left, key=lambda z: z[0])]}
        if not left:
            check["verdict"] = "explains every significant driver signature"
            rnd.checks.append(check)
            rnd.added, rnd.decision = t.name, _added_text(t, "it explains every significant driver signature")
            break
        # the generic alternative: every driver signature the candidate leaves unexplained
        dcols = np.concatenate([z[2] for z in left])
        names_left = ", ".join(f"{d.group} on {d.axis}" for _, d, _, _ in sorted(left, key=lambda z: z[0]))
        sc_c = score_test(A, b, np.concatenate([rs.null, dcols]), idx, scale=rs.prior_sigma[idx],
                          min_eig=dopt.identifiable, scale_factor=vf)
        thr_c = float(stats.chi2.isf(dopt.alpha / m, max(sc_c.dof, 1)))
        check["candidate_given_drivers"] = {"statistic": sc_c.statistic, "dof": sc_c.dof, "threshold": thr_c}
        if sc_c.dof and sc_c.statistic > thr_c:
            check["verdict"] = (f"needed beyond the driver signatures it leaves ({names_left}): "
                                f"{sc_c.statistic:.1f} > {thr_c:.1f}")
            rnd.checks.append(check)
            rnd.added, rnd.decision = t.name, _added_text(
                t, "still significant given the driver signatures it does not explain")
            break
        check["verdict"] = (f"not added: it only mimics driver signatures the catalogue lacks ({names_left}): "
                            f"{sc_c.statistic:.1f} <= {thr_c:.1f} given those drivers")
        rnd.checks.append(check)
    if allow_add and significant and rnd.added is None:
        rnd.decision = ("no candidate added: every significant candidate only mimics a driver signature "
                        "that the catalogue lacks")
    rnd.seconds = time.perf_counter() - t0
    return rnd


def diagnose(experiment, *, options=None, diagnosis=DiagnosisOptions(), truth=None, progress=None):
    """The closed loop on one experiment.

    Parameters
    ----------
    experiment : graph_calib.experiment.Experiment
    options : graph_calib.calibrate.CalibrationOptions, optional
        The declared model (grade, keyframes, effects already modelled, priors).
    diagnosis : DiagnosisOptions
    truth : graph_calib.experiment.Result, optional
        A simulator's truth: the error of the declared parameters before and after.
    progress : callable, optional
        Called with one-line messages.

    Returns
    -------
    Diagnosis
    """
    t_start = time.perf_counter()
    say = progress or (lambda msg: None)
    options = CalibrationOptions() if options is None else options
    problem = build_problem(experiment, options=options)
    options = replace(options, t_ref_degC=problem.model.t_ref_degC)   # one T_ref for every model
    candidates = tuple(diagnosis.candidates or effects.FURTHER_EFFECTS)
    m = problem.model
    say(f"declared model: {m.layout.size} parameters, {m.n_keyframes} keyframes; factor graph ...")
    gr = _solve(problem, options)
    before = _make_stage(problem, gr, options, diagnosis, truth=truth, say=say)
    fixed = {s: r.sigmas for s, r in before.results.items()}
    rounds, added = [], []
    while True:
        allow = len(added) < diagnosis.max_added
        rnd = _round(len(rounds) + 1, experiment, options, problem, gr, diagnosis, candidates, allow_add=allow,
                     say=say)
        rounds.append(rnd)
        say(f"round {rnd.index}: {rnd.decision}")
        if rnd.added is None:
            break
        added.append(rnd.added)
        options = _with_effects(options, tuple(options.model.extra_effects) + (rnd.added,))
        new = problem.with_effects(options.model.extra_effects)
        x0 = new.model.layout.embed(problem.model.layout, gr.x)
        say(f"re-solving with {rnd.added} ...")
        gr = _solve(new, options, initial=(gr.attitudes, x0))
        problem = new
    after = before if not added else _make_stage(problem, gr, options, diagnosis, truth=truth,
                                                 fixed_sigmas=fixed, say=say)
    last = rounds[-1]
    signature = sorted((d for d in last.drivers if d.significant), key=lambda d: d.log10_p)
    e = experiment
    context = {
        "n_samples": e.n_samples, "duration_s": float(e.t[-1] - e.t[0] + 1.0 / e.rate_hz),
        "rate_hz": float(e.rate_hz), "table": e.table is not None, "grade": options.model.grade,
        "keyframes": int(m.n_keyframes), "keyframe_s": float(options.model.keyframe_s),
        "t_ref_degC": float(m.t_ref_degC), "solvers": list(diagnosis.solvers),
        "temperature_range_degC": [float(m.temperatures.min()), float(m.temperatures.max())],
        "truth": truth is not None,
    }
    source = e.source.rsplit("/", 1)[-1] if e.source else ""
    return Diagnosis(source=source, added=added, unexplained=bool(signature), signature=signature, rounds=rounds,
                     before=before, after=after, options=diagnosis, context=context,
                     seconds=time.perf_counter() - t_start)
