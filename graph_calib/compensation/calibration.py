r"""A calibration that applies itself: one result's parameters through the one sensor model.

A :class:`Calibration` holds what a solver estimated (or what a simulator's truth
file states) for one experiment: a :class:`graph_calib.sensors.params.Layout`, the
calibration vector ``x`` of that layout, and the reference temperature
``t_ref_degC`` of its temperature coefficients.  It never restates the sensor
equations: every number goes through :mod:`graph_calib.sensors.sensor_model`, the model
the simulator and both solvers share (``shared/spec/model.md``).

Applying it
    :meth:`Calibration.correct` turns an experiment's raw increments into the
    angular rate ``omega_ib_b`` and the specific force ``f_b`` by the inverse
    model (:func:`graph_calib.sensors.sensor_model.correct`), with the context the
    solvers prepare (:class:`graph_calib.model.PreparedRecord`):
    sensor temperature offsets from ``t_ref_degC``, their rate over a 60 s
    window, the other triad's raw signal and the slope-limited derivatives of the
    raw signals.  :func:`correct_record` is that inversion on a prepared record
    (:func:`prepare`) with one calibration vector, or with one per sample (a
    stitched calibration or a compensation table evaluated at each sample's
    sensor temperatures, :mod:`graph_calib.compensation`).
    :meth:`Calibration.corrected` and :func:`corrected_experiment` turn the
    corrected rate and force back into increments: an experiment whose
    ``dtheta``/``dv`` are corrected (``graph-calib apply``).

The errors it predicts
    :meth:`Calibration.sensor_errors` gives, for true signals, what the forward
    model adds to them, ``measure(signal) - signal = Phi(signal) @ x``.  It is
    evaluated as ``Phi @ x`` from the model's own term features
    (:func:`graph_calib.sensors.sensor_model.sample_features`), summed in the order of
    :func:`graph_calib.sensors.sensor_model.measure`: the same number, without
    subtracting the signal from ``signal + error`` (whose rounding at 0.35 rad/s,
    3e-17 rad/s, is 3e-8 of a remaining error of 0.0002 deg/h; validation
    compares such differences).  :func:`triad_errors` is the same sum for
    element values that change from row to row (a calibration already evaluated
    at each row's temperature) and, with ``power=2``, the variance of the error
    from independent element sigmas.

Files
    :meth:`Calibration.to_dict` / :meth:`Calibration.from_dict`: a JSON-ready
    document with ``format`` :data:`CALIBRATION_FORMAT` and ``version``
    :data:`CALIBRATION_VERSION`; a newer version is refused.

Examples
--------
>>> from graph_calib.sensors.params import Layout
>>> cal = Calibration(layout=Layout(("gyro.bias", "gyro.scale")), x=[1e-6, 0, 0, 1e-4, 0, 0], t_ref_degC=20.0)
>>> e_gyro, e_accel = cal.sensor_errors(np.array([[0.5, 0.0, 0.0]]), np.array([[0.0, 0.0, 9.8]]),
...                                     dT=np.zeros((1, 6)))
>>> float(e_gyro[0, 0])  # 1e-6 + 1e-4 * 0.5
5.1e-05
>>> Calibration.from_dict(cal.to_dict()).x.tolist() == cal.x.tolist()
True
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np

from graph_calib.sensors import sensor_model
from graph_calib.errors import InputError
from graph_calib.model import ModelOptions, PreparedRecord
from graph_calib.sensors.params import Layout, split_element_name
from graph_calib.sensors.sensor_model import correct_sample, sample_features, term_rows
from graph_calib import kernel_cache

kernel_cache.install()     # before the first kernel: cached kernels stamped with the sources they depend on

#: ``format`` of a calibration document.
CALIBRATION_FORMAT = "imu-calibration-coefficients"
#: ``version`` of the calibration document this code writes; it reads this one and older.
CALIBRATION_VERSION = 1



# ---------------------------------------------------------------------------
# the error sum of the sensor model
# ---------------------------------------------------------------------------


@numba.njit(cache=True)
def _error_sum(rows, X, power, s, dT, dTdt, other, domega, dsig, out):
    """``out[j, axis_r] = sum_r X[j, col_r] * feature_r(j) ** power`` (``X`` of one row broadcasts).

    With ``power = 1`` and one row of ``X`` this is the error that
    :func:`graph_calib.sensors.sensor_model.measure` adds to the signal, summed in the same
    order, without the signal.
    """
    R = rows.shape[0]
    feat = np.empty(R)
    per_row = X.shape[0] > 1
    for j in range(s.shape[0]):
        sample_features(rows, s[j], dT[j], dTdt[j], other[j], domega[j], dsig[j], feat)
        k = j if per_row else 0
        out[j, 0] = 0.0
        out[j, 1] = 0.0
        out[j, 2] = 0.0
        for r in range(R):
            phi = feat[r] if power == 1 else feat[r] * feat[r]
            out[j, rows[r, 1]] += X[k, rows[r, 0]] * phi


def _writable(a):
    """``a`` C-contiguous and writable (copied only when it is not): a read-only array is another numba type,
    so a kernel would compile a second signature for it (docs/performance.md, "Compiling the kernels")."""
    a = np.ascontiguousarray(a)
    return a if a.flags.writeable else a.copy()


def _rows3(a, n, what):
    """``a`` as a contiguous float array of shape (n, 3); None gives zeros, shape (3,) broadcasts."""
    if a is None:
        return np.zeros((n, 3))
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        a = np.broadcast_to(a, (n, 3))
    if a.shape != (n, 3):
        raise ValueError(f"{what} must have shape ({n}, 3) or (3,), got {a.shape}")
    return np.ascontiguousarray(a)


def triad_errors(layout, X, triad, signal, *, dT=None, dTdt=None, other=None, domega=None, dsignal=None,
                 power=1):
    """The sensor model's error sum of one triad, ``Phi(signal) @ x`` per row.

    Parameters
    ----------
    layout : graph_calib.sensors.params.Layout
    X : array_like, shape (layout.size,) or (N, layout.size)
        Calibration vector, or one per row (SI).
    triad : {"gyro", "accel"}
    signal : array_like, shape (N, 3)
        True angular rate ``omega_ib_b`` (rad/s) or specific force ``f_b`` (m/s^2).
    dT, dTdt, other, domega, dsignal : array_like, shape (N, 3), optional
        The context of :func:`graph_calib.sensors.sensor_model.measure` (zero when None).
    power : {1, 2}
        1: the error, ``measure(signal) - signal``; 2: ``sum_r X[col_r] feature_r^2``, the
        variance of the error when ``X`` holds independent element variances.

    Returns
    -------
    ndarray, shape (N, 3)
        rad/s or m/s^2 (their squares for ``power=2``).
    """
    if power not in (1, 2):
        raise ValueError(f"power must be 1 or 2, got {power!r}")
    signal = np.atleast_2d(np.asarray(signal, dtype=float))
    n = signal.shape[0]
    signal = _rows3(signal, n, "signal")
    X = _writable(np.atleast_2d(np.asarray(X, dtype=float)))
    if X.shape[1] != layout.size or X.shape[0] not in (1, n):
        raise ValueError(f"X must have shape ({layout.size},) or ({n}, {layout.size}), got {X.shape}")
    out = np.empty((n, 3))
    _error_sum(term_rows(layout, triad), X, int(power), signal, _rows3(dT, n, "dT"), _rows3(dTdt, n, "dTdt"),
               _rows3(other, n, "other"), _rows3(domega, n, "domega"), _rows3(dsignal, n, "dsignal"), out)
    return out


def _columns6(a, n, what):
    """``a`` (N, 6) or (6,) as (N, 6), or None."""
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        a = np.broadcast_to(a, (n, 6))
    if a.shape != (n, 6):
        raise ValueError(f"{what} must have shape ({n}, 6) or (6,), got {a.shape}")
    return a


# ---------------------------------------------------------------------------
# the inverse model on a record, one calibration vector or one per sample
# ---------------------------------------------------------------------------


@numba.njit(cache=True)
def _inverse_rows(rows, X, m, dT, dTdt, other, domega, dsig, n_iter, out, want_jacobian):
    """:func:`graph_calib.sensors.sensor_model.correct` with row ``j`` of ``X`` for sample ``j``.

    The same per-sample call of :func:`graph_calib.sensors.sensor_model.correct_sample`
    as the model's own loop, only the calibration vector changes from row to row.
    ``want_jacobian`` is False, passed from Python so that ``correct_sample`` keeps the one signature that
    :func:`graph_calib.sensors.sensor_model.correct` compiles (a literal ``False`` here would compile another).
    """
    work = np.empty((8, 3))
    J = np.zeros((3, 1))
    for j in range(m.shape[0]):
        correct_sample(rows, X[j], m[j], dT[j], dTdt[j], other[j], domega[j], dsig[j], n_iter, out[j], J,
                       want_jacobian, work)


def prepare(experiment, *, t_ref_degC=None):
    """The solvers' data preparation of an experiment (:class:`graph_calib.model.PreparedRecord`).

    What :meth:`Calibration.correct` and :func:`correct_record` feed the inverse
    model with: raw sample means, their slope-limited derivatives, the sensor
    temperatures' offsets from ``t_ref_degC`` (default: the experiment's mean)
    and their rates over a 60 s window.
    """
    return PreparedRecord(experiment, keyframe_s=ModelOptions.keyframe_s, t_ref_degC=t_ref_degC)


def correct_record(layout, X, record, *, n_newton=ModelOptions.n_newton):
    """Calibrated angular rate and specific force of a prepared record, through the inverse sensor model.

    Parameters
    ----------
    layout : graph_calib.sensors.params.Layout
    X : array_like, shape (layout.size,) or (N, layout.size)
        One calibration vector for every sample, or one per sample (a calibration
        evaluated at each sample's temperatures, :mod:`graph_calib.compensation`), SI.
        Temperature coefficients in ``layout`` act on ``dT = T - record.t_ref_degC``.
    record : graph_calib.model.PreparedRecord
        From :func:`prepare`.
    n_newton : int, optional
        Newton steps of the inversion (one is exact for a model linear in the signal).

    Returns
    -------
    omega_ib_b : ndarray, shape (N, 3)
        rad/s, mean over each sample interval.
    f_b : ndarray, shape (N, 3)
        m/s^2, mean over each sample interval.

    Notes
    -----
    The accelerometers are corrected first, with ``dT`` and ``dT/dt`` of their
    sensors, ``other = w``, ``domega = dw/dt``, ``dsignal = df/dt`` (``w`` and the
    derivatives from the raw sample means); then the gyros with ``dT`` and ``dT/dt``
    of theirs, ``other = f_b`` (the *calibrated* specific force, for
    ``g_sensitivity``), ``domega = dsignal = dw/dt``: as the solvers feed the model.
    With one vector this is :func:`graph_calib.sensors.sensor_model.correct_pair` itself;
    with one per sample the same per-sample inversion, bit for bit where the rows
    are equal.
    """
    r = record
    X = np.asarray(X, dtype=float)
    if X.ndim == 1:
        return sensor_model.correct_pair(layout, X, r.w_raw, r.f_raw, dTg=r.dTg, dTdtg=r.dTdtg, dTa=r.dTa,
                                         dTdta=r.dTdta, domega=r.dw_raw, df=r.df_raw, n_iter=n_newton)
    n = r.w_raw.shape[0]
    if X.shape != (n, layout.size):
        raise ValueError(f"X must have shape ({layout.size},) or ({n}, {layout.size}), got {X.shape}")
    X = _writable(X)
    f_b = np.empty((n, 3))
    w_b = np.empty((n, 3))
    # accelerometers first: the gyros' g-sensitivity sees the calibrated specific force
    for triad, m, ctx, s in (("accel", r.f_raw, (r.dTa, r.dTdta, r.w_raw, r.dw_raw, r.df_raw), f_b),
                             ("gyro", r.w_raw, (r.dTg, r.dTdtg, f_b, r.dw_raw, r.dw_raw), w_b)):
        # fresh writable copies (f_b is one): one numba signature for both triads
        _inverse_rows(term_rows(layout, triad), X, np.array(m, dtype=float),
                      *(np.array(c, dtype=float) for c in ctx), int(n_newton), s, False)
    return w_b, f_b


def corrected_experiment(experiment, omega_ib_b, f_b, *, note=""):
    """The experiment with corrected increments ``dtheta = omega_ib_b dt``, ``dv = f_b dt``.

    Everything else (times, temperatures, table readings, identity) is kept;
    ``note`` becomes the first line of the description, the old description
    follows.  Corrected increments are what the sensors would have delivered
    without their errors: calibrating them again finds (near) zero sensor errors,
    and correcting them again subtracts the errors a second time.
    """
    dt = experiment.dt[:, None]
    omega_ib_b = np.asarray(omega_ib_b, dtype=float)
    f_b = np.asarray(f_b, dtype=float)
    if omega_ib_b.shape != experiment.dtheta.shape or f_b.shape != experiment.dv.shape:
        raise ValueError(f"corrected signals of shape {omega_ib_b.shape} and {f_b.shape} for an experiment of "
                         f"{experiment.n_samples} samples")
    description = "\n".join(s for s in (note, experiment.description) if s)
    return replace(experiment, dtheta=omega_ib_b * dt, dv=f_b * dt, description=description)


# ---------------------------------------------------------------------------
# the calibration
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Calibration:
    """One experiment's calibration, applied through :mod:`graph_calib.sensors.sensor_model`.

    Attributes
    ----------
    layout : graph_calib.sensors.params.Layout
        The parameters the calibration holds.
    x : ndarray, shape (layout.size,)
        Their values, SI (read-only).  Elements the source did not give are zero.
    t_ref_degC : float
        Reference temperature of the temperature coefficients, degC.
    sigma : ndarray, shape (layout.size,), or None
        One sigma of each element (None for a truth); carried, not used here.
    source : str
        Where the calibration came from (experiment file name).

    Notes
    -----
    Compared by identity (``eq=False``): two calibrations with equal numbers are
    compared by their fields, ``a.x.tolist() == b.x.tolist()`` and so on.
    """

    layout: Layout
    x: np.ndarray
    t_ref_degC: float
    sigma: np.ndarray | None = None
    source: str = ""

    def __post_init__(self):
        if not isinstance(self.layout, Layout):
            raise TypeError(f"layout must be a graph_calib.sensors.params.Layout, got {type(self.layout).__name__}")
        for name in ("x", "sigma"):
            v = getattr(self, name)
            if v is None:
                continue
            v = np.array(v, dtype=float)
            if v.shape != (self.layout.size,):
                raise ValueError(f"{name} must have shape ({self.layout.size},) for this layout, got {v.shape}")
            v.setflags(write=False)
            object.__setattr__(self, name, v)
        t = float(self.t_ref_degC)
        if not np.isfinite(t):
            raise ValueError(f"t_ref_degC must be finite, got {self.t_ref_degC!r}")
        object.__setattr__(self, "t_ref_degC", t)

    # -- building ----------------------------------------------------------------

    @classmethod
    def from_values(cls, values, *, t_ref_degC, sigmas=None, parameters=(), source=""):
        """A calibration from flat element values.

        Parameters
        ----------
        values : dict
            ``{flat element name: value}``, SI (``gyro.misalignment.zx``, ``time_lag.table``).
        t_ref_degC : float
        sigmas : dict, optional
            ``{flat element name: one sigma}``; elements missing from it get NaN.
        parameters : sequence of str, optional
            Parameters to hold besides those ``values`` names (their missing elements are zero).
        source : str, optional

        Returns
        -------
        Calibration
            Layout: every parameter named, catalogue order; elements not given are zero.
        """
        names = set(parameters)
        for flat in values:
            names.add(split_element_name(flat)[0])
        layout = Layout(tuple(names))
        sigma = None if sigmas is None else layout.from_dict(sigmas, missing=np.nan)
        return cls(layout=layout, x=layout.from_dict(values), t_ref_degC=t_ref_degC, sigma=sigma, source=source)

    @classmethod
    def from_result(cls, result):
        """The calibration a result states (:class:`graph_calib.records.experiment.Result`, estimate or truth).

        Layout: the result's ``effects`` and every parameter its ``values`` name;
        ``x`` its values, ``t_ref_degC`` its reference temperature, ``sigma`` its
        sigmas (None for a truth).  A truth file's curvature remainder
        (``extra.simulation.unmodelled``) is not part of the result's values and is
        left out; add it with :meth:`from_values` where it is wanted.
        """
        return cls.from_values(result.values, t_ref_degC=result.t_ref_degC, sigmas=result.sigmas,
                               parameters=tuple(result.effects), source=result.source)

    def values(self):
        """``{flat element name: value}``, SI."""
        return self.layout.to_dict(self.x)

    # -- applying ----------------------------------------------------------------

    def correct(self, experiment, *, n_newton=ModelOptions.n_newton):
        """Calibrated angular rate and specific force of every sample of an experiment.

        The inverse model :func:`graph_calib.sensors.sensor_model.correct`, fed as the
        solvers feed it: with ``w = dtheta / dt`` and ``f = dv / dt`` the raw
        sample means, the gyros get ``dT`` and ``dT/dt`` of the gyro sensors,
        ``other = f``, ``domega = dsignal = dw/dt``; the accelerometers ``dT`` and
        ``dT/dt`` of theirs, ``other = w``, ``domega = dw/dt``, ``dsignal =
        df/dt``.  ``dT = T - t_ref_degC`` (this calibration's reference, not the
        experiment's mean); the data are prepared by the solvers' own
        :class:`graph_calib.model.PreparedRecord`.

        Parameters
        ----------
        experiment : graph_calib.records.experiment.Experiment
        n_newton : int, optional
            Newton steps of the inversion (default: the solvers' default).  One is
            exact for a model linear in the signal (every declared term).

        Returns
        -------
        omega_ib_b : ndarray, shape (N, 3)
            Angular rate against inertial space, rad/s, mean over each sample interval.
        f_b : ndarray, shape (N, 3)
            Specific force, m/s^2, mean over each sample interval.
        """
        return correct_record(self.layout, self.x, prepare(experiment, t_ref_degC=self.t_ref_degC),
                              n_newton=n_newton)

    def corrected(self, experiment, *, n_newton=ModelOptions.n_newton, note=None):
        """The experiment with its increments corrected: :meth:`correct` times each sample interval.

        ``note`` (default: this calibration's source and reference temperature)
        heads the description; see :func:`corrected_experiment`.
        """
        if note is None:
            note = f"corrected with the calibration of {self.source or 'an unnamed source'} " \
                   f"(T_ref {self.t_ref_degC:.2f} degC)"
        return corrected_experiment(experiment, *self.correct(experiment, n_newton=n_newton), note=note)

    def sensor_errors(self, omega_b, f_b, *, dT, dTdt=None, domega_b=None, df_b=None):
        """The sensor errors the calibration predicts: ``measure(signal) - signal`` for each triad.

        ``Phi(signal) @ x`` of :mod:`graph_calib.sensors.sensor_model` (module docstring:
        the same sum as ``measure`` forms, without the signal).  The gyros see
        ``other = f_b``, the accelerometers ``other = omega_b``, as in the solvers.

        Parameters
        ----------
        omega_b : array_like, shape (N, 3)
            Angular rate ``omega_ib_b``, rad/s.
        f_b : array_like, shape (N, 3)
            Specific force, m/s^2.
        dT : array_like, shape (N, 6) or (6,)
            Temperature of gyro x, y, z and accel x, y, z minus ``t_ref_degC``, degC.
        dTdt : array_like, shape (N, 6) or (6,), optional
            Their rate, degC/s (``*.bias_dtdt``); zero when None.
        domega_b : array_like, shape (N, 3), optional
            Angular acceleration, rad/s^2 (``accel.size_effect``); zero when None.
        df_b : array_like, shape (N, 3), optional
            Rate of the specific force, m/s^3 (``time_lag.accel``); zero when None.

        Returns
        -------
        e_gyro : ndarray, shape (N, 3)
            rad/s.
        e_accel : ndarray, shape (N, 3)
            m/s^2.
        """
        omega_b = np.atleast_2d(np.asarray(omega_b, dtype=float))
        f_b = np.atleast_2d(np.asarray(f_b, dtype=float))
        n = omega_b.shape[0]
        dT = _columns6(dT, n, "dT")
        dTdt = _columns6(dTdt, n, "dTdt")
        e_gyro = triad_errors(self.layout, self.x, "gyro", omega_b, dT=dT[:, :3],
                              dTdt=None if dTdt is None else dTdt[:, :3], other=f_b, domega=domega_b,
                              dsignal=domega_b)
        e_accel = triad_errors(self.layout, self.x, "accel", f_b, dT=dT[:, 3:],
                               dTdt=None if dTdt is None else dTdt[:, 3:], other=omega_b, domega=domega_b,
                               dsignal=df_b)
        return e_gyro, e_accel

    # -- files -------------------------------------------------------------------

    def to_dict(self):
        """JSON-ready document: ``format``, ``version``, ``source``, ``t_ref_degC``, ``parameters``,
        ``values`` and ``sigmas`` (``{flat element: value}``, SI; ``sigmas`` null for a truth)."""
        return {
            "format": CALIBRATION_FORMAT, "version": CALIBRATION_VERSION, "source": self.source,
            "t_ref_degC": self.t_ref_degC, "parameters": list(self.layout.names),
            "values": self.layout.to_dict(self.x),
            "sigmas": None if self.sigma is None else self.layout.to_dict(self.sigma),
        }

    @classmethod
    def from_dict(cls, doc):
        """The calibration of a :meth:`to_dict` document.

        Raises
        ------
        graph_calib.errors.InputError
            Not a calibration document, a version newer than :data:`CALIBRATION_VERSION`
            (written by a newer graph-calib), an unknown parameter or a missing element.
        """
        if not isinstance(doc, dict):
            raise InputError(f"a calibration document is a JSON object, got {type(doc).__name__}")
        fmt = doc.get("format")
        if fmt != CALIBRATION_FORMAT:
            raise InputError(f"format is {fmt!r}, expected {CALIBRATION_FORMAT!r}", dataset="format")
        version = doc.get("version")
        if isinstance(version, bool) or not isinstance(version, int) or version < 1:
            raise InputError(f"version {version!r} is not a calibration version (a positive integer)",
                             dataset="version")
        if version > CALIBRATION_VERSION:
            raise InputError(f"version {version} is newer than this graph-calib reads (up to "
                             f"{CALIBRATION_VERSION}); read it with the graph-calib that wrote it, or a newer one",
                             dataset="version")
        try:
            layout = Layout(tuple(doc["parameters"]))
        except KeyError as exc:
            raise InputError(str(exc.args[0]) if exc.args else "missing", dataset="parameters") from None
        values = doc.get("values") or {}
        missing = [n for n in layout.element_names() if n not in values]
        if missing:
            raise InputError(f"no value for {', '.join(missing)}", dataset="values")
        unknown = [n for n in values if n not in set(layout.element_names())]
        if unknown:
            raise InputError(f"{', '.join(unknown)} not in the parameters {list(layout.names)}", dataset="values")
        if "t_ref_degC" not in doc:
            raise InputError("no reference temperature", dataset="t_ref_degC")
        sigmas = doc.get("sigmas")
        return cls(layout=layout, x=layout.from_dict(values), t_ref_degC=doc["t_ref_degC"],
                   sigma=None if sigmas is None else layout.from_dict(sigmas, missing=np.nan),
                   source=str(doc.get("source", "")))


__all__ = ["Calibration", "triad_errors", "prepare", "correct_record", "corrected_experiment", "CALIBRATION_FORMAT",
           "CALIBRATION_VERSION"]
