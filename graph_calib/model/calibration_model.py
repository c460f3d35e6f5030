"""The calibration problem of one experiment: a prepared record, the layout it can inform, priors and noise.

:class:`CalibrationModel` is a thin object over :class:`graph_calib.model.record.PreparedRecord`
(the data), the sensor terms of its layout, the preintegration and the factors: every solver sees
the problem only through :meth:`CalibrationModel.preintegrate`, the factor methods (rotation, gravity,
encoder and, on request, still) and the two prior residuals, so that the equations are written once.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from graph_calib.constants import omega_ie_n as _omega_ie_n
from graph_calib.sensors.effects import uninformed, with_lower_orders
from graph_calib.model import factors, guided_turns
from graph_calib.model.options import ModelOptions
from graph_calib.model.preintegration import SensorTerms, preintegrate
from graph_calib.model.record import PreparedRecord
from graph_calib.model.unresolved import heading_drift_direction, without_data_along
from graph_calib.sensors.params import Layout, grade as _grade
from graph_calib.navigation.rotations import quat_to_dcm

#: Prior sigma of the first attitude when valid table readings give it (faceplate
#: attitude through the nominal mounting; the mounting error is estimated), rad.
TABLE_ALIGNMENT_SIGMA = 0.05

#: A ``still`` factor's sigma over its keyframe, as a fraction of the gyro's noise over it
#: (:meth:`CalibrationModel.still_factors`): small enough that the rest's gyro integral is judged by the gyro's
#: noise alone (one per cent of the pair's variance), large enough to keep the fused rows well conditioned.
STILL_FRACTION = 0.1

#: Gyrocompass heading sigma (rad, :func:`gyrocompass_attitude_sigma`) from which on the Earth rate is
#: taken not to resolve the heading: the linearised covariance is then not trusted along a heading
#: drift (:meth:`CalibrationModel.unresolved_directions`).
HEADING_UNRESOLVED_SIGMA = 1.0


def gyrocompass_attitude_sigma(options, *, latitude_rad):
    """Prior sigma (rad) of a gyrocompassed first attitude: gyro-bias prior over the horizontal Earth rate.

    Between :attr:`TABLE_ALIGNMENT_SIGMA` and pi (about 0.1 rad
    for a navigation-grade unit, pi for consumer MEMS).  ``options`` is a
    :class:`ModelOptions` (its grade and any ``gyro.bias`` prior override).
    """
    g = _grade(options.grade)
    horizontal = float(np.hypot(*_omega_ie_n(latitude_rad)[:2]))
    bias = float(np.max((options.prior_sigma or {}).get("gyro.bias", g.prior_sigma["gyro.bias"])))
    return float(min(np.pi, max(TABLE_ALIGNMENT_SIGMA, bias / max(horizontal, 1e-12))))


#: How many preintegrations :func:`reusing_preintegrations` holds (the last ones formed).
REUSED_PREINTEGRATIONS = 2

_REUSE = []    # the held preintegrations while a ``reusing_preintegrations`` block runs (else empty, off)


@contextmanager
def reusing_preintegrations():
    """Within the block, :meth:`CalibrationModel.preintegrate` of a point it has just formed returns that one.

    A preintegration depends on the prepared record, the layout, ``n_newton`` and the calibration ``x`` only
    (not on the noise or the variance factors), so the solves of one record one after the other (the
    variance components' solves, each warm-started from the last solution, and the fit statistics at each
    solution: :mod:`graph_calib.solvers.variance`; the closed loop's solves and fit statistics:
    :mod:`graph_calib.diagnosis.loop`) need not form the same one again.  The last
    :data:`REUSED_PREINTEGRATIONS` formed are held (strongly: for a 3 h record 0.15-0.4 GB each, with the
    layout) until the block ends, so it is meant for one record's calibration or diagnosis (a campaign
    worker's job), not held across a worker's jobs.  Blocks nest; the outermost one frees them.
    """
    outer = bool(_REUSE)
    if not outer:
        _REUSE.append([])
    try:
        yield
    finally:
        if not outer:
            _REUSE.clear()


class CalibrationModel:
    """The calibration problem of one experiment: data, layout, priors, noise, factors.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    options : ModelOptions
    t_ref_degC : float, optional
        Reference temperature; default the mean of the six sensors' temperatures.
    static_mask : ndarray of bool, shape (N,), optional
        Samples known to be static (gravity counts only there when ``options.moving_sigma`` is set).
    short_rests : array_like of int, shape (R, 2), optional
        The short rests among them, each then a static keyframe (:class:`PreparedRecord`).

    Attributes
    ----------
    record : graph_calib.model.record.PreparedRecord
        The prepared data (shared by every layout of the same record: :meth:`with_effects`).
    layout : graph_calib.sensors.params.Layout
        What is estimated: the declared model, the requested further effects, less what the record
        cannot inform (``auto_excluded``) and ``options.exclude``.
    noise : graph_calib.model.factors.Noise
    initial_attitude_sigma : float
        Prior sigma of the first keyframe attitude, rad.
    """

    def __init__(self, experiment, *, options=ModelOptions(), t_ref_degC=None, static_mask=None, short_rests=None):
        record = PreparedRecord(experiment, keyframe_s=options.keyframe_s, t_ref_degC=t_ref_degC,
                                static_mask=static_mask, short_rests=short_rests)
        self._setup(record, options)

    @classmethod
    def from_record(cls, record, *, options=ModelOptions()):
        """The model of an already prepared record (its keyframes and ``T_ref`` are the record's)."""
        self = cls.__new__(cls)
        self._setup(record, options)
        return self

    def with_effects(self, extra_effects):
        """The same record and options with ``extra_effects`` as the further effects modelled."""
        return CalibrationModel.from_record(self.record,
                                            options=replace(self.options, extra_effects=tuple(extra_effects)))

    def with_options(self, **changes):
        """The same record with its :class:`ModelOptions` changed as ``changes`` say."""
        return CalibrationModel.from_record(self.record, options=replace(self.options, **changes))

    def _setup(self, record, options):
        self.record = record
        self.options = options
        self.grade = _grade(options.grade)
        self.gyro_noise = float(options.gyro_noise if options.gyro_noise is not None else self.grade.gyro_noise)
        self.accel_noise = float(options.accel_noise if options.accel_noise is not None else self.grade.accel_noise)
        self.encoder_noise = float(options.encoder_noise if options.encoder_noise is not None
                                   else self.grade.encoder_noise)
        self.gyro_quantization = float(options.gyro_quantization or 0.0)
        self.noise = factors.Noise(gyro=self.gyro_noise, accel=self.accel_noise, encoder=self.encoder_noise,
                                   variance_factors=dict(options.variance_factors or {}),
                                   gyro_quantization=self.gyro_quantization)
        # what the record can inform decides the layout
        self.auto_excluded = self._unobservable()
        exclude = tuple(sorted(set(options.exclude) | set(self.auto_excluded)))
        # a curve's order comes with the orders below it (with_lower_orders)
        self.layout = Layout.declared(extra=with_lower_orders(options.extra_effects), exclude=exclude)
        self.initial_attitude_sigma = self._initial_attitude_sigma(record.experiment)
        self.terms = SensorTerms.of(self.layout)
        self.still_keys = self._still_keys()
        # a Ferraris session's turns about the vertical, where the rests are known and no table reads the attitude
        self.turns = guided_turns.find_guided_turns(record) if self.turn_sigma is not None and not record.has_table \
            else np.zeros((0, 2), dtype=np.int64)
        self.turn_keys = np.repeat(self.turns[:, 0], self.turns[:, 1] - self.turns[:, 0])

    # -- the record's figures every caller needs ----------------------------

    @property
    def experiment(self):
        return self.record.experiment

    @property
    def t_ref_degC(self):
        return self.record.t_ref_degC

    @property
    def temperatures(self):
        """Sensor temperatures (N, 6), degC."""
        return self.record.temperatures

    @property
    def n_keyframes(self):
        return self.record.n_keyframes

    @property
    def t_key(self):
        """Keyframe boundary times (K+1,), s."""
        return self.record.t_key

    @property
    def omega_ie_n(self):
        return self.record.omega_ie_n

    def _unobservable(self):
        """Parameters the record cannot inform, left out of the layout (sorted tuple).

        What each parameter needs is in the effect registry (:func:`graph_calib.sensors.effects.uninformed`).
        Without a table nothing ties the attitude to the faceplate or to a fixed
        rotation centre: ``mount``, ``time_lag.table``, ``damping.stiffness`` and
        ``lever_arm`` go.  With a table whose valid readings are all taken at rest
        (the usual bench: encoders trusted only in static positions) a time lag
        changes no measurement, so ``time_lag.table`` goes too; estimating it
        would only return its prior mean as if it were a result.
        """
        rec = self.record
        return uninformed(has_table=rec.experiment.table is not None, has_valid_readings=rec.has_valid_readings,
                          readings_in_motion=rec.readings_in_motion)

    #: Prior sigma of the first attitude when valid table readings give it (faceplate
    #: attitude through the nominal mounting; the mounting error is estimated), rad.
    TABLE_ALIGNMENT_SIGMA = 0.05

    def _initial_attitude_sigma(self, experiment):
        """Prior sigma of the first keyframe attitude (isotropic), rad.

        With valid table readings the alignment takes the table's attitude:
        :attr:`TABLE_ALIGNMENT_SIGMA`.  Otherwise the heading comes from
        gyrocompassing, good to about the gyro bias over the horizontal Earth
        rate (0.1 rad for a navigation-grade unit, nothing at all for consumer
        MEMS, whose bias is a hundred times the Earth rate): the sigma is that,
        capped at pi.  The whole record then fixes the heading through the Earth
        rate; a tight prior around a wrong gyrocompass heading would instead turn
        the Earth-rate compensation into a false gyro bias (4 sigma on the
        consumer hand-held scenario).
        """
        if self.options.initial_attitude_sigma is not None:
            return float(self.options.initial_attitude_sigma)
        tab = experiment.table
        if tab is not None and np.any(tab.valid):
            return TABLE_ALIGNMENT_SIGMA
        return gyrocompass_attitude_sigma(self.options, latitude_rad=experiment.latitude_rad)

    # -- what the record cannot resolve -------------------------------------

    def unresolved_directions(self, x):
        """Calibration directions this record cannot resolve beyond their priors.

        A heading drift is a g-sensitivity ``kappa (I + S + M_g)`` to the gyros
        (:mod:`graph_calib.model.unresolved`); only a heading reference or the Earth rate tells them
        apart.  Listed when the layout holds ``gyro.g_sensitivity``, the record has no valid table
        reading and the gyros cannot gyrocompass (:func:`gyrocompass_attitude_sigma` at least
        :data:`HEADING_UNRESOLVED_SIGMA`): a hand-held consumer record.

        Parameters
        ----------
        x : ndarray, shape (P,)
            The calibration (the direction depends on its gyro scale and misalignment).

        Returns
        -------
        names : tuple of str
            ``("heading drift",)`` or ``()``.
        directions : ndarray, shape (D, P)
            Unit directions.
        """
        if ("gyro.g_sensitivity" not in self.layout or self.record.has_valid_readings
                or gyrocompass_attitude_sigma(self.options, latitude_rad=self.experiment.latitude_rad)
                < HEADING_UNRESOLVED_SIGMA):
            return (), np.zeros((0, self.layout.size))
        return ("heading drift",), heading_drift_direction(self.layout, np.asarray(x, dtype=float))[None, :]

    def resolved_covariance(self, x, covariance):
        """A solver's covariance with the data's information along :meth:`unresolved_directions` removed.

        :func:`graph_calib.model.unresolved.without_data_along` with this model's prior sigmas: such a
        direction keeps its prior sigma, every other element what the data give with it free.
        Unchanged (the same array) when nothing is unresolved.

        Parameters
        ----------
        x : ndarray, shape (P,)
        covariance : ndarray, shape (P, P)

        Returns
        -------
        ndarray, shape (P, P)
        """
        _, U = self.unresolved_directions(x)
        if U.shape[0] == 0:
            return covariance
        return without_data_along(covariance, self.prior()[1], U)

    # -- priors -------------------------------------------------------------

    def prior(self):
        """Prior mean and one sigma of the calibration vector, shapes (P,), (P,).

        The mean is zero but for the parameters ``ModelOptions.prior_mean`` names; the sigmas the grade's but
        for those ``ModelOptions.prior_sigma`` names.
        """
        sig = self.grade.prior_vector(self.layout)
        for name, value in (self.options.prior_sigma or {}).items():
            if name in self.layout:
                sig[self.layout.slice(name)] = value
        mean = self.layout.zeros()
        for name, value in (self.options.prior_mean or {}).items():
            if name in self.layout:
                mean[self.layout.slice(name)] = value
        return mean, sig

    def priors_used(self):
        """``{parameter name: sigma}`` actually used (for the result file)."""
        _, sig = self.prior()
        return {n: sig[self.layout.slice(n)].tolist() for n in self.layout.names}

    def attitude_prior(self, R0, *, R_prior):
        """The first keyframe attitude's prior residual (:func:`graph_calib.model.factors.attitude_prior`)."""
        return factors.attitude_prior(R0, R_prior=R_prior, sigma=self.initial_attitude_sigma)

    @property
    def segment_keys(self):
        """Keyframe index of each segment's first keyframe (``/imu/segment``), shape (S,); ``[0]`` for one."""
        return self.record.segment_keys

    def segment_priors(self, q_nb0):
        """The prior attitudes ``C_nb`` of the segments' first keyframes, shape (S, 3, 3).

        Parameters
        ----------
        q_nb0 : array_like, shape (4,) or (S, 4)
            The alignment of each segment (scalar first); one quaternion for a record of one segment.
        """
        q = np.atleast_2d(np.asarray(q_nb0, dtype=float))
        S = self.segment_keys.size
        if q.shape != (S, 4):
            raise ValueError(f"the record has {S} segment(s): q_nb0 must be of shape ({S}, 4)"
                             + (" or (4,)" if S == 1 else "") + f", not {np.shape(q_nb0)}")
        return quat_to_dcm(q)

    def attitude_priors(self, R, *, R_priors):
        """The prior residual of every segment's first keyframe attitude.

        Parameters
        ----------
        R : ndarray, shape (K+1, 3, 3)
            Keyframe attitudes.
        R_priors : ndarray, shape (S, 3, 3)
            The segments' alignments (:meth:`segment_priors`).

        Returns
        -------
        list of (int, graph_calib.model.factors.PriorResidual)
            ``(keyframe, prior residual)`` per segment, in order.
        """
        R_priors = np.asarray(R_priors, dtype=float).reshape(-1, 3, 3)
        return [(int(k), self.attitude_prior(R[k], R_prior=Rp)) for k, Rp in zip(self.segment_keys, R_priors)]

    def calibration_prior(self, x):
        """The calibration vector's prior residual (:func:`graph_calib.model.factors.calibration_prior`)."""
        mean, sigma = self.prior()
        return factors.calibration_prior(x, mean=mean, sigma=sigma)

    # -- preintegration and attitudes ----------------------------------------

    def preintegrate(self, x):
        """Preintegrate every keyframe and encoder reading at calibration ``x`` (P,).

        Inside :func:`reusing_preintegrations`, one formed there at the same record, layout, ``n_newton`` and
        ``x`` (bit for bit) is returned instead.
        """
        if not _REUSE:
            return preintegrate(self.record, self.terms, x, layout=self.layout, n_newton=self.options.n_newton)
        held = _REUSE[0]
        n_newton = int(self.options.n_newton)
        for p in held:
            if (p.record is self.record and p.n_newton == n_newton and p.layout == self.layout
                    and np.array_equal(p.x_lin, x)):
                return p
        p = preintegrate(self.record, self.terms, x, layout=self.layout, n_newton=n_newton)
        held[:] = [p, *held[:REUSED_PREINTEGRATIONS - 1]]
        return p

    def propagate(self, R0, preint, x):
        """Dead-reckoned attitude at every keyframe boundary, shape (K+1, 3, 3).

        ``R0`` (3, 3), or (S, 3, 3) with one attitude per segment: each segment starts again from its
        own (:attr:`segment_keys`).
        """
        dR = preint.corrected(x).dR
        E = self.record.earth_turn(self.record.T_key)
        R0 = np.asarray(R0, dtype=float).reshape(-1, 3, 3)
        starts = dict(zip(self.segment_keys.tolist(), R0))
        R = np.empty((self.n_keyframes + 1, 3, 3))
        R[0] = R0[0]
        for k in range(self.n_keyframes):  # keyframe rate, not sample rate
            R[k + 1] = starts[k + 1] if k + 1 in starts else E[k] @ R[k] @ dR[k]
        return R

    # -- factors --------------------------------------------------------------

    def _still_keys(self):
        """The keyframes with a ``still`` factor (:attr:`ModelOptions.still_at_rest`): static ones with a rotation
        factor, where the rests are known."""
        rec = self.record
        if not self.options.still_at_rest or not rec.static_known:
            return np.zeros(0, dtype=np.int64)
        k = np.asarray(rec.rotation_keys, dtype=np.int64)
        s = np.asarray(rec.static_key, dtype=bool)
        # a rest's first and last keyframes are left out where the rest has keyframes inside: the static detector's
        # window smears a rest's edges, and an edge keyframe may hold the start or end of a turn; a rest of one
        # keyframe (a short rest on its own grid, cut at the detector's short windows) is kept
        before = np.concatenate([[False], s[:-1]])
        after = np.concatenate([s[1:], [False]])
        keep = s & ((before & after) | (~before & ~after))
        return k[keep[k]]

    def _still_variance(self):
        """Each still factor's variance per axis before the kind's variance factor, rad^2 (F,):
        :data:`STILL_FRACTION` of the gyro's noise over the keyframe, and a ring-laser gyro's quantization at its two
        ends (the keyframe attitudes are the indicated ones)."""
        T = self.record.T_key[self.still_keys]
        return (STILL_FRACTION * self.noise.gyro) ** 2 * T + 2.0 * self.noise.gyro_quantization ** 2

    def still_share(self):
        """The still factor's share of the variance of each rest's measurement row after
        :func:`graph_calib.model.still_fusion.fuse_still`, (F,); the rest is the gyro's noise over the keyframe
        (the rotation kind's), whose variance component is estimated from those rows too
        (:mod:`graph_calib.model.redundancy`, :mod:`graph_calib.solvers.variance`)."""
        vf = self.noise.variance_factors
        gyro = float(vf.get("rotation", 1.0)) * self.noise.gyro ** 2 * self.record.T_key[self.still_keys]
        still = float(vf.get("still", 1.0)) * self._still_variance()
        return still / (gyro + still)

    def still_factors(self, R, preint, x):
        """:func:`graph_calib.model.factors.still_factors` of this model's rests.

        Each factor's sigma is :data:`STILL_FRACTION` of the gyro's own noise over the keyframe (a unit at rest
        turns by less than its gyros can tell), with a ring-laser gyro's quantization at the keyframe's two ends
        added (the keyframe attitudes are the indicated ones); the kind's variance factor (``still``) scales it.
        """
        return self.noise.scaled("still", factors.still_factors(self.record, R, preint, x, keys=self.still_keys,
                                                                 sigma=np.sqrt(self._still_variance())))

    @property
    def turn_sigma(self):
        """The guided turns' protocol sigma, rad, or None (:attr:`ModelOptions.guided_turns`)."""
        g = self.options.guided_turns
        if g is None or g is False:
            return None
        return guided_turns.DEFAULT_SIGMA if g is True else float(g)

    def turn_factors(self, R, preint, x):
        """:func:`graph_calib.model.guided_turns.turn_factors` of this model's guided turns; the kind's variance factor
        (``turn``) scales them."""
        return self.noise.scaled(guided_turns.KIND, guided_turns.turn_factors(
            self.record, R, preint, x, turns=self.turns, sigma=self.turn_sigma or 0.0, gyro_noise=self.noise.gyro))

    def rotation_factors(self, R, preint, x):
        """:func:`graph_calib.model.factors.rotation_factors` of this model."""
        return self.noise.scaled("rotation", factors.rotation_factors(self.record, R, preint, x, noise=self.noise))

    def gravity_factors(self, R, preint, x):
        """:func:`graph_calib.model.factors.gravity_factors` of this model."""
        return self.noise.scaled("gravity", factors.gravity_factors(
            self.record, R, preint, x, layout=self.layout, noise=self.noise, moving_sigma=self.options.moving_sigma,
            sway_sigma=self.options.sway_sigma))

    def encoder_factors(self, R, preint, x):
        """:func:`graph_calib.model.factors.encoder_factors` of this model (it applies the variance factors: its
        gyro term takes the rotation kind's)."""
        return factors.encoder_factors(self.record, R, preint, x, layout=self.layout, noise=self.noise)


__all__ = ["CalibrationModel", "STILL_FRACTION", "reusing_preintegrations", "REUSED_PREINTEGRATIONS", "gyrocompass_attitude_sigma",
           "TABLE_ALIGNMENT_SIGMA", "HEADING_UNRESOLVED_SIGMA"]
