"""How an experiment is turned into a calibration problem: :class:`ModelOptions`."""

from __future__ import annotations

from dataclasses import dataclass, field

#: ``ModelOptions.noise_identified`` key of the sway (m/s^2) a table-less record's rests show when no sway term models
#: it (:func:`graph_calib.records.problem.sway_from_static`); the verdict notes it.
SWAY_SEEN_KEY = "sway_seen_mps2"
#: ``ModelOptions.noise_identified`` key of gyro outputs that sit at their extreme in runs with no cut after them
#: (:func:`graph_calib.records.saturation.flat_tops`: a saturated gyro the record was not cut for).
SATURATION_SEEN_KEY = "gyro_flat_tops"


@dataclass(frozen=True)
class ModelOptions:
    """How an experiment is turned into a calibration problem.

    Attributes
    ----------
    keyframe_s : float
        Keyframe interval, s.
    grade : str or None
        IMU grade for the priors (``params.GRADES``).  None: chosen from the record's rests by
        :func:`graph_calib.records.problem.build_problem` (:func:`graph_calib.records.grade_choice.choose_grade`, as
        the commands do; its reason in ``grade_choice``); a model made without a record (a design's prediction)
        takes :data:`graph_calib.sensors.params.DEFAULT_GRADE`.
    extra_effects : tuple of str
        Further effects of ``model.md`` added to the declared model.
    exclude : tuple of str
        Declared parameters not estimated (e.g. ``lever_arm`` without a table).
    prior_sigma : dict
        Overrides of the grade's prior sigmas, ``{parameter name: sigma}`` (SI; a scalar for every element or
        one value per element).
    prior_mean : dict
        Prior means other than zero, ``{parameter name: value per element}`` (SI): what the campaign already
        knows of a parameter (the joint curve's curvature at a subrange's ``T_ref``,
        :mod:`graph_calib.campaign.curvature_wave`).  A parameter not named has mean zero.
    gyro_noise, accel_noise, encoder_noise : float or None
        Overrides of the grade's noise (rad/sqrt(s), m/s/sqrt(s), rad).
    gyro_quantization : float or None
        White error of the gyros' integrated angle at each sample end, rad (IEEE ``Q``: a ring-laser
        gyro's quantization; :class:`graph_calib.model.factors.Noise`); None: none.
    initial_attitude_sigma : float or None
        Prior sigma of the first keyframe attitude around the alignment, rad.
        None: what the alignment can know (:attr:`CalibrationModel.initial_attitude_sigma`).
    moving_sigma : float, ``"estimate"`` or None
        Without a table the bench may translate: gravity measurements of keyframes
        that are not static get this sigma (m/s^2).  None: every keyframe counts (without a table
        :func:`graph_calib.records.problem.build_problem` makes it 1 m/s^2); ``"estimate"``: 1 m/s^2 to
        start with, then estimated with the variance components (:mod:`graph_calib.solvers.variance`).
    sway_sigma : float, ``"estimate"`` or None
        The bench's own acceleration at rest (a hand holding the unit sways it), averaged over a
        keyframe: one sigma (m/s^2) added in quadrature to every gravity measurement.  None: zero;
        ``"estimate"``: :func:`graph_calib.records.problem.build_problem` estimates it from the static
        intervals (:func:`graph_calib.records.problem.sway_from_static`, docs/model.md).
    still_at_rest : bool
        Whether a static keyframe's attitude at its end is its start's (the ``still`` factors,
        :func:`graph_calib.model.factors.still_factors`: the rests' gyro integrals then inform the gyro biases, as a
        Ferraris calibration's rests do).  Where the rests are known (a static mask); off by default (docs/model.md,
        "A unit at rest does not turn").
    guided_turns : float or bool or None
        A Ferraris session's full turns about the vertical, slid flat and pressed against a guide before and after
        (:mod:`graph_calib.model.guided_turns`): the protocol's one sigma per axis, rad (True, the default: 0.5
        deg); None or False: such turns are motion like any other.  Found where the rests are known and no table
        reads the attitude (a record without such turns is not changed).
    n_newton : int
        Newton steps of the sensor-model inversion.
    noise_source : dict
        Where each white-noise level came from, ``{"gyro" | "accel" | "encoder": "identified" | "declared" |
        "grade"}`` (:func:`graph_calib.records.problem.noise_options`); empty: not said.
    noise_identified : dict
        What the record showed of its noise (JSON-ready figures for the result's ``noise`` block); under
        :data:`SWAY_SEEN_KEY` the sway its rests show when ``sway_sigma`` is None (m/s^2; absent when none is seen);
        under :data:`SATURATION_SEEN_KEY` the gyro flat tops the record was not cut for (absent when none).
    grade_choice : dict
        How ``build_problem`` chose the grade when none was given
        (:meth:`graph_calib.records.grade_choice.GradeChoice.to_json`; empty: given).
    variance_factors : dict
        ``{kind: factor}``: each measurement kind's (``rotation``, ``gravity``, ``encoder``) covariance
        multiplied by its factor (variance components, :mod:`graph_calib.solvers.variance`); a kind not
        named keeps 1.
    gravity_gyro_shared : bool
        A keyframe's rotation factor made independent of its gravity factor, with which it shares the gyros' noise
        (:mod:`graph_calib.model.gravity_gyro_noise`); False: the two taken as independent, the start a cold solve
        passes through (:func:`graph_calib.solvers.registry.solve`).
    heading_axes : bool
        The static keyframes' gravity factors and the conditioned rotation factors given to the solvers in body axes,
        which a heading common to every attitude does not turn (:mod:`graph_calib.model.heading_axes`); False: in
        level axes, as a cold start's first solve takes them (their turn's Jacobian term grows with the residual).
    """

    keyframe_s: float = 1.0
    grade: str | None = None
    extra_effects: tuple = ()
    exclude: tuple = ()
    prior_sigma: dict | None = None
    prior_mean: dict | None = None
    gyro_noise: float | None = None
    accel_noise: float | None = None
    encoder_noise: float | None = None
    gyro_quantization: float | None = None
    initial_attitude_sigma: float | None = None
    moving_sigma: float | str | None = None
    sway_sigma: float | str | None = None
    still_at_rest: bool = False
    guided_turns: float | bool | None = True
    n_newton: int = 2
    noise_source: dict = field(default_factory=dict)
    noise_identified: dict = field(default_factory=dict)
    variance_factors: dict = field(default_factory=dict)
    grade_choice: dict = field(default_factory=dict)
    gravity_gyro_shared: bool = True
    heading_axes: bool = True
