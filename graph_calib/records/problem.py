"""One experiment made ready for any solver: the shared model, its static intervals and its alignment.

>>> problem = build_problem(experiment, options=CalibrationOptions())      # doctest: +SKIP
>>> problem.model.layout.size, problem.q_nb0                                # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from graph_calib.model import CalibrationModel, gyrocompass_attitude_sigma
from graph_calib.model.options import SATURATION_SEEN_KEY, SWAY_SEEN_KEY
from graph_calib.noise import find_rests, identify_noise, table_noise
from graph_calib.noise.identify import ENCODER_NOISE_FLOOR, MIN_DWELL_DOF, TERMS
from graph_calib.noise.rests import segment_rests
from graph_calib.options import CalibrationOptions
from graph_calib.sensors.params import DEFAULT_GRADE, grade
from graph_calib.navigation.alignment import Alignment, alignment
from graph_calib.errors import InputError
from graph_calib.records.plausibility import check_record
from graph_calib.records.saturation import flat_tops
from graph_calib.records.grade_choice import MIN_STATIC_S, choose_grade


@dataclass(frozen=True)
class Problem:
    """A calibration model with its initial attitude, ready for any solver.

    Attributes
    ----------
    model : graph_calib.model.CalibrationModel
    q_nb0 : ndarray, shape (4,), or (S, 4) for a record of S > 1 segments
        Attitude ``q_nb`` (scalar first) at the start of the record (of each segment), from the
        alignment.
    alignment : graph_calib.navigation.alignment.Alignment
        How the first ``q_nb0`` was found.
    segment_alignments : tuple of graph_calib.navigation.alignment.Alignment
        How each segment's was found (``(alignment,)`` for one segment); the intervals are sample
        indices of the whole record.
    noise : graph_calib.noise.NoiseIdentification or None
        What the record showed of its noise (:func:`graph_calib.noise.identify_noise`).
    """

    model: CalibrationModel
    q_nb0: np.ndarray
    alignment: Alignment
    segment_alignments: tuple = ()
    noise: object = None

    def with_effects(self, extra_effects):
        """The same record, static intervals and alignment, with ``extra_effects`` as the further effects."""
        return replace(self, model=self.model.with_effects(extra_effects))


#: How far outside a record's temperatures a reference temperature may lie, degC: a campaign's common reference sits
#: within its span (-40..85 degC at most); beyond, the temperature coefficients are extrapolated so far that the
#: fit is ill-posed (1000 degC for a record at -9 degC ended in an indeterminate system).
T_REF_REACH_DEGC = 125.0


def check_t_ref(experiment, t_ref_degC):
    """Refuse a reference temperature that is not a number or lies beyond :data:`T_REF_REACH_DEGC` of the record's
    temperatures (:class:`~graph_calib.errors.InputError`)."""
    t = float(t_ref_degC)
    T = np.asarray(experiment.temperature, dtype=float)
    lo, hi = float(np.min(T)), float(np.max(T))
    if not np.isfinite(t) or t < lo - T_REF_REACH_DEGC or t > hi + T_REF_REACH_DEGC:
        raise InputError(f"{t:g} degC lies beyond {T_REF_REACH_DEGC:g} degC of the record's temperatures "
                         f"({lo:.1f}..{hi:.1f} degC): the temperature coefficients would be extrapolated that far; give "
                         "a reference temperature near the data", path=experiment.source or None, dataset="t_ref_degC")


def build_problem(experiment, *, options=CalibrationOptions(), check=True):
    """Set up the shared model of ``experiment`` and align it.

    Without a table, gravity measurements count only where the IMU is static
    (``ModelOptions.moving_sigma`` then defaults to 1 m/s^2 for moving keyframes).
    A record whose gyro increments cannot be in radians (degrees written for radians, rates for
    increments: :func:`graph_calib.records.plausibility.check_record`) is refused first, with an
    :class:`~graph_calib.errors.InputError` (exit 2 on the command line, nothing written), and so is
    a record cut together without ``/imu/segment`` (:func:`graph_calib.records.plausibility.check_continuity`).

    A record of several segments (``/imu/segment``) is detected static and aligned segment by
    segment: each segment's first keyframe gets its own attitude prior, from a static interval of
    that segment (levelling, and gyrocompassing or the table for the heading).

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    options : CalibrationOptions
    check : bool
        False: the record is known to pass those checks (a campaign's joint solve, on a file whose own job
        built its problem from the same bytes), and they are not run again.

    Returns
    -------
    Problem
    """
    if check:
        check_record(experiment)
    if options.t_ref_degC is not None:
        check_t_ref(experiment, options.t_ref_degC)
    model_options = options.model
    # each segment its own threshold: its first seconds' unless they are loud (graph_calib.noise.rests)
    # the rests as a hand makes them: detect_static's, and the short rests (0.5-2 s) between them, each of which
    # then gets a static keyframe of its own (PreparedRecord)
    segs = segment_rests(experiment)
    bounds = [(a, b) for a, b, _, _, _ in segs]
    pieces = [p for _, _, p, _, _ in segs]
    parts = [(long, short) for _, _, _, long, short in segs]
    static_per = [np.concatenate(lp) for lp in parts]
    static_per = [st[np.argsort(st[:, 0], kind="stable")] for st in static_per]
    static = np.concatenate([np.asarray(st, dtype=np.int64).reshape(-1, 2) + a
                             for st, (a, _) in zip(static_per, bounds)])
    short = np.concatenate([np.asarray(sh, dtype=np.int64).reshape(-1, 2) + a for (_, sh), (a, _) in zip(parts, bounds)])
    static_mask = None
    if experiment.table is None:
        static_mask = np.zeros(experiment.n_samples, dtype=bool)
        for a, b in static:
            static_mask[a:b] = True
        if model_options.moving_sigma is None:
            model_options = replace(model_options, moving_sigma=1.0)
    identified = identify_noise(experiment, keyframe_s=model_options.keyframe_s, rests=find_rests(experiment))
    if model_options.grade is None:
        model_options = _with_grade_chosen(experiment, identified, model_options)
    model_options = noise_options(identified, model_options)
    if isinstance(model_options.moving_sigma, str):
        if model_options.moving_sigma != "estimate":
            raise InputError(f"moving_sigma must be a number of m/s^2, 'estimate' or None, not "
                             f"{model_options.moving_sigma!r}", dataset="moving_sigma")
        # 1 m/s^2 to start with, the variance components estimate it (solvers/variance.py; here, after
        # noise_options, which writes noise_source afresh); a table's record has every keyframe static
        model_options = replace(model_options, moving_sigma=None) if static_mask is None else replace(
            model_options, moving_sigma=1.0, noise_source={**model_options.noise_source, "moving": MOVING_ESTIMATED})
    accel_noise = model_options.accel_noise if model_options.accel_noise is not None \
        else grade(model_options.grade).accel_noise
    if isinstance(model_options.sway_sigma, str):
        if model_options.sway_sigma != "estimate":
            raise InputError(f"sway_sigma must be a number of m/s^2, 'estimate' or None, not "
                             f"{model_options.sway_sigma!r}", dataset="sway_sigma")
        model_options = replace(model_options, sway_sigma=sway_from_static(
            experiment, static, keyframe_s=model_options.keyframe_s, accel_noise=accel_noise))
    elif model_options.sway_sigma is None and static_mask is not None:
        # a sway the rests show although no sway term is asked for: the result records it (noise.identified) and the
        # verdict notes it (solvers/verdict.py), since a short record's residual test does not see it
        seen = sway_from_static(experiment, static, keyframe_s=model_options.keyframe_s, accel_noise=accel_noise)
        if seen > 0.0:
            model_options = replace(model_options, noise_identified={**model_options.noise_identified,
                                                                     SWAY_SEEN_KEY: seen})
    # a gyro that sits at its extreme in runs the record was not cut for (records/saturation.py): the verdict notes it
    tops = flat_tops(experiment, rests=static)
    if tops is not None:
        model_options = replace(model_options, noise_identified={**model_options.noise_identified,
                                                                 SATURATION_SEEN_KEY: tops})
    method = "table" if (experiment.table is not None and np.any(experiment.table.valid)) else "gyrocompass"
    aligned = []
    for i, (piece, st, (a, b)) in enumerate(zip(pieces, static_per, bounds)):
        if len(bounds) > 1 and not len(st):
            raise InputError(f"segment {i} (samples {a}..{b - 1}) has no static interval to align it: each piece "
                             f"of a record cut together needs a rest of a few seconds for its own initial attitude",
                             path=experiment.source or None, dataset="/imu/segment", index=a)
        al, table_failed = _align(piece, interval=tuple(st[0]) if len(st) else None, method=method)
        if table_failed and model_options.initial_attitude_sigma is None:
            # the table could not give the attitude: the prior is as loose as gyrocompassing is
            model_options = replace(model_options, initial_attitude_sigma=gyrocompass_attitude_sigma(
                model_options, latitude_rad=experiment.latitude_rad))
        aligned.append(replace(al, interval=(al.interval[0] + a, al.interval[1] + a)) if a else al)
    model = CalibrationModel(experiment, options=model_options, t_ref_degC=options.t_ref_degC, static_mask=static_mask,
                             short_rests=short if static_mask is not None else None)
    enc, enc_dof = table_noise(model.record.reading_scatter)
    identified = replace(identified, encoder=enc, encoder_dof=enc_dof)
    if enc is not None and model_options.encoder_noise is None:
        model_options = replace(model_options, encoder_noise=enc, noise_source={
            **model_options.noise_source, "encoder": "identified"},
            noise_identified={**model_options.noise_identified, "encoder": {"sigma_rad": enc, "dof": enc_dof}})
        model = CalibrationModel.from_record(model.record, options=model_options)
    elif enc is None and enc_dof >= MIN_DWELL_DOF and model_options.encoder_noise is None:
        # the dwells' readings do not scatter (below ENCODER_NOISE_FLOOR): their noise is not identified, and the
        # grade's is no measurement of it (the verdict says what that does to the sigmas: solvers/verdict.py)
        model_options = replace(model_options, noise_identified={
            **model_options.noise_identified,
            "encoder": {"sigma_rad": None, "dof": enc_dof, "below_rad": ENCODER_NOISE_FLOOR}})
        model = CalibrationModel.from_record(model.record, options=model_options)
    q_nb0 = aligned[0].q_nb0 if len(aligned) == 1 else np.array([al.q_nb0 for al in aligned])
    return Problem(model=model, q_nb0=q_nb0, alignment=aligned[0], segment_alignments=tuple(aligned),
                   noise=identified)


def _align(experiment, *, interval, method):
    """``(alignment, whether the table failed and gyrocompassing was used)`` of one segment."""
    try:
        return alignment(experiment, interval=interval, method=method), False
    except Exception:
        if method != "table":
            raise
        return alignment(experiment, interval=interval, method="gyrocompass"), True


#: ``noise_source["moving"]`` of a model whose moving keyframes' gravity sigma the variance components estimate.
MOVING_ESTIMATED = "variance components"

#: The sway is estimated only when the keyframe means scatter this much more than white noise would
#: (in variance); below, it is taken as zero.
SWAY_VARIANCE_FACTOR = 2.0


def sway_from_static(experiment, static, *, keyframe_s, accel_noise):
    """The bench's own acceleration at rest over a keyframe, one sigma, m/s^2 (0 when not seen).

    In every static interval the specific force is averaged over blocks of one keyframe (a rest
    shorter than two keyframes: over its two halves); the sample variance of those block means about
    their interval's mean, less what white noise explains (``accel_noise^2 / T_block``), pooled over
    the intervals and the axes, is the hand's sway (coloured, 0.3-3 Hz, which a per-sample variance
    does not reach) a gravity factor of a resting keyframe sees.  When that, plus the white part of a
    keyframe (``accel_noise^2 / keyframe_s``), exceeds the white part by more than
    :data:`SWAY_VARIANCE_FACTOR` the sway's root is returned, else 0.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    static : ndarray of int, shape (P, 2)
        Static intervals, sample indices.
    keyframe_s : float
    accel_noise : float
        White-noise density, m/s/sqrt(s).

    Returns
    -------
    float
    """
    per = max(1, int(round(keyframe_s * experiment.rate_hz)))
    f = experiment.dv / experiment.dt[:, None]
    excess, dof = 0.0, 0
    for a, b in np.asarray(static, dtype=np.int64).reshape(-1, 2):
        m = min(per, (b - a) // 2)          # a rest shorter than two keyframes: two blocks of half its length
        if m < 1:
            continue
        nb = (b - a) // m
        means = f[a:a + nb * m].reshape(nb, m, 3).mean(axis=1)
        excess += float(np.sum((means - means.mean(axis=0)) ** 2)) - 3 * (nb - 1) * accel_noise**2 / (m / experiment.rate_hz)
        dof += 3 * (nb - 1)
    if dof == 0:
        return 0.0
    white = accel_noise**2 / (per / experiment.rate_hz)
    var = excess / dof + white
    return float(np.sqrt(var - white)) if var > SWAY_VARIANCE_FACTOR * white else 0.0


#: A density identified below this fraction of the grade's is not taken (the grade's is): a record simulated
#: without noise shows none, and a weight without bound would make the priors and the kinds' balance meaningless.
IDENTIFIED_FLOOR_FRACTION = 0.1


def _terms_json(sn):
    """The compact figures of a :class:`graph_calib.noise.SensorNoise` for the result's ``noise`` block."""
    out = {"density": sn.density, "density_sigma": sn.density_sigma, "keyframe_s": sn.keyframe_s,
           "rest_s": sn.allan.rest_s}
    for name, _, _ in TERMS:
        out[name] = {"value": sn.term(name),
                     "sigma": float(np.sqrt(np.mean([c.sigmas[name] ** 2 for c in sn.channels]))),
                     "supported": [ax for ax, c in zip("xyz", sn.channels) if name in c.supported],
                     "channels": [c.values[name] for c in sn.channels]}
    out["estimator"] = [c.estimator for c in sn.channels]
    out["allan"] = {"tau_s": sn.allan.tau.tolist(), "adev": sn.allan.adev.tolist(),
                    "rel_sigma": sn.allan.rel_sigma.tolist()}
    return out


def _with_grade_chosen(experiment, identified, model_options):
    """``model_options`` with the grade the record's rests choose (no grade given: the Python API's default), and how
    it was chosen in ``grade_choice``.

    As the commands choose it (:func:`graph_calib.records.grade_choice.choose_grade`), except that a record whose
    rests cannot tell (none of 2 s, or noise-free simulated data) takes :data:`graph_calib.sensors.params.DEFAULT_GRADE`
    with that said in ``grade_choice`` (the result's), where the commands refuse it naming ``--grade``.
    """
    try:
        choice = choose_grade(experiment, identification=identified, keyframe_s=model_options.keyframe_s).to_json()
    except InputError:
        choice = {"grade": DEFAULT_GRADE, "reason": f"{DEFAULT_GRADE}, the default: the record has no rest of "
                  f"{MIN_STATIC_S:g} s with its noise to choose the grade from (ModelOptions(grade=...) names it)"}
    return replace(model_options, grade=choice["grade"], grade_choice=choice)


def noise_options(identified, model_options):
    """The model options with the white-noise densities the solvers use, and where each came from.

    A density set in the options is ``declared`` and kept; otherwise the one the record shows
    (:func:`graph_calib.noise.identify_noise`, the density that governs a keyframe) is ``identified``;
    a record whose rests are too short to show it, or that shows less than
    :data:`IDENTIFIED_FLOOR_FRACTION` of the grade's (noise-free simulated data), takes the grade's
    (``grade``).  An identified gyro density is split (unless ``gyro_quantization`` is declared): the
    white rate noise ``N`` (the IEEE term, floored at :data:`IDENTIFIED_FLOOR_FRACTION` of the grade's)
    becomes ``gyro_noise`` and the quantization ``Q`` ``gyro_quantization``, since the keyframe attitudes
    absorb ``Q`` (:class:`graph_calib.model.factors.Noise`); without quantization ``N`` is the
    density.  The table readings' noise is identified later, from the prepared record's dwells
    (:func:`build_problem`).

    Parameters
    ----------
    identified : graph_calib.noise.NoiseIdentification
    model_options : graph_calib.model.ModelOptions

    Returns
    -------
    graph_calib.model.ModelOptions
        With ``gyro_noise``, ``accel_noise``, ``gyro_quantization``, ``noise_source`` and ``noise_identified``
        set.
    """
    g = grade(model_options.grade)
    source, figures, values = {}, {}, {}
    quantization = model_options.gyro_quantization
    for sensor, declared, floor in (("gyro", model_options.gyro_noise, g.gyro_noise),
                                    ("accel", model_options.accel_noise, g.accel_noise)):
        sn = getattr(identified, sensor)
        if sn is not None:
            figures[sensor] = _terms_json(sn)
        if declared is not None:
            values[sensor], source[sensor] = float(declared), "declared"
        elif sn is not None and sn.density >= IDENTIFIED_FLOOR_FRACTION * floor:
            values[sensor], source[sensor] = sn.density, "identified"
            if sensor == "gyro" and quantization is None:
                # the keyframe attitudes absorb the angle's quantization (graph_calib.model.factors.Noise): the
                # rotation factors get the white rate noise N, the attitude's readers Q
                # (q_eff^2 = N^2 + 2 Q^2 / T, graph_calib.noise.identify)
                quantization = sn.term("quantization")
                values[sensor] = max(sn.term("white"), IDENTIFIED_FLOOR_FRACTION * floor)
        else:
            values[sensor], source[sensor] = floor, "grade"
    source["encoder"] = "declared" if model_options.encoder_noise is not None else "grade"
    return replace(model_options, gyro_noise=values["gyro"], accel_noise=values["accel"], noise_source=source,
                   noise_identified=figures, gyro_quantization=quantization)


__all__ = ["Problem", "SWAY_VARIANCE_FACTOR", "IDENTIFIED_FLOOR_FRACTION", "build_problem", "noise_options",
           "sway_from_static"]
