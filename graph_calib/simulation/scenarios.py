r"""Scenarios: complete synthetic experiments and campaigns with their truth.

A scenario is a function ``build(*, rng, **options) -> Simulation``; the
registry :data:`SCENARIOS` maps its name to it.  A :class:`Simulation` holds
the campaign information (IMU id, grade) and one :class:`ExperimentPlan` per
experiment; a plan makes its experiment on demand (so a long campaign is written
one experiment at a time) and always makes the same one: each plan owns a seed
drawn from ``rng`` when the scenario is built.

Randomness comes only from the ``numpy.random.Generator`` passed in; how an
experiment uses its seed is described in :mod:`graph_calib.simulation.experiments`.

Use :func:`simulate` to build a scenario by name and
:func:`graph_calib.simulation.writing.write_simulation` to write the experiment
files, ``*.truth.json`` and ``campaign.toml``.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import numpy as np

from graph_calib.sensors import effects
from graph_calib.constants import ARCSEC_TO_RAD
from graph_calib.errors import InputError
from graph_calib.simulation.design import NAV_DESIGN, SHORT_DESIGN
from graph_calib.simulation.experiments import (
    SENSOR_CHANNELS,
    SENSOR_TEMPERATURE_MAP,
    _make_handheld_experiment,
    _make_table_experiment,
)
from graph_calib.simulation.truth import ImuTruth, draw_imu

#: Default bench: latitude (deg) and local gravity (m/s^2) of Moscow.
DEFAULT_LATITUDE_DEG = 55.7
DEFAULT_GRAVITY_MPS2 = 9.8155

#: The six subranges of the navigation campaign, degC.
CAMPAIGN_SUBRANGES = ((-10.0, 0.0), (0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, 40.0), (40.0, 50.0))


@dataclass(frozen=True)
class ExperimentPlan:
    """An experiment of a scenario, made on demand by :meth:`run` (always the same one)."""

    file_name: str
    make: Callable = field(repr=False)
    summary: str = ""

    def run(self):
        """Make the experiment: a :class:`~graph_calib.simulation.experiments.SimulatedExperiment`."""
        return self.make()


@dataclass(frozen=True)
class Simulation:
    """A built scenario: campaign information and one plan per experiment.

    Attributes
    ----------
    scenario : str
    imu_id : str
    grade : str
    plans : tuple of ExperimentPlan
    imu : ImuTruth
        The simulated IMU (truth over the whole temperature range).
    exclude : tuple of str
        Declared parameters the set-up does not have (written to the manifest's ``[model] exclude``).
    info : dict
        Options the scenario was built with (for summaries).
    """

    scenario: str
    imu_id: str
    grade: str
    plans: tuple
    imu: ImuTruth
    exclude: tuple = ()
    info: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.plans)

    def run(self):
        """Every experiment, as a list of :class:`~graph_calib.simulation.experiments.SimulatedExperiment`."""
        return [p.run() for p in self.plans]

    def pairs(self):
        """Every experiment as ``(Experiment, truth Result)`` pairs."""
        return [(s.experiment, s.truth) for s in self.run()]

    def temperature_range(self):
        """``(lowest, highest)`` chamber set-point of the scenario's turntable experiments, degC."""
        subs = self.info.get("subranges")
        if subs:
            return float(min(a for a, _ in subs)), float(max(b for _, b in subs))
        kw = self._table_keywords()
        return float(kw["start_degC"]), float(kw["start_degC"] + kw["span_degC"])

    def further_experiment(self, *, file_name, seed, hours, start_degC, span_degC, rate_hz=None,
                           description="", tag=""):
        """Another turntable experiment of the same IMU, bench and rotation design.

        Its own programme and noise (``seed``), ``hours`` long, the chamber taking the
        sensors from ``start_degC`` through ``span_degC`` (degC); used for independent
        validation records.  Returns a
        :class:`~graph_calib.simulation.experiments.SimulatedExperiment`; ``ValueError``
        for a scenario without a turntable (hand-held).
        """
        make = self.plans[0].make
        kw = dict(self._table_keywords())
        kw.update(file_name=file_name, seed=int(seed), duration_s=float(hours) * 3600.0,
                  start_degC=float(start_degC), span_degC=float(span_degC), description=description, tag=tag)
        if rate_hz is not None:
            kw["rate_hz"] = float(rate_hz)
        return make.func(*make.args, **kw)

    def _table_keywords(self):
        make = self.plans[0].make if self.plans else None
        if not (isinstance(make, partial) and make.func is _make_table_experiment):
            raise ValueError(f"scenario {self.scenario!r} has no turntable experiment to extend")
        return make.keywords


def _label(v):
    s = f"{v:g}"
    return s.replace("-", "m").replace(".", "p")


# ---------------------------------------------------------------------------
# scenarios
# ---------------------------------------------------------------------------


#: Longest simulated record, h: a campaign's longest subrange is some hours; 1e5 h ran until it was killed.
MAX_HOURS = 100.0


def _check_common(hours, rate_hz, effect_scale, effect_names):
    if hours is not None and not (np.isfinite(hours) and hours > 0):
        raise InputError(f"--hours must be a positive number, got {hours!r}")
    if hours is not None and hours > MAX_HOURS:
        raise InputError(f"--hours must be at most {MAX_HOURS:g} (a record of {hours:g} h is no bench's), got {hours!r}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"rate_hz must be positive, got {rate_hz!r}")
    if not (np.isfinite(effect_scale) and effect_scale >= 0):
        raise InputError(f"--effect-scale must be a non-negative number, got {effect_scale!r}")
    for e in effect_names:
        if e not in effects.FURTHER_EFFECTS:
            raise InputError(f"unknown effect {e!r}; known: {', '.join(effects.FURTHER_EFFECTS)}")


#: Noise options of the table scenarios (True noise at a multiple of the grade's, the table readings' own
#: noise, a ring-laser gyro's quantization, a record that begins in motion).
NOISE_OPTIONS = ("noise_factor", "encoder_noise_arcsec", "gyro_quantization_arcsec", "start_in_motion")


def _noise_keywords(*, noise_factor, encoder_noise_arcsec=None, gyro_quantization_arcsec=0.0):
    """The builders' noise keywords from the scenario options (refused with InputError when bad)."""
    if not (np.isfinite(noise_factor) and noise_factor >= 0):
        raise InputError(f"noise_factor must be a non-negative number, got {noise_factor!r}")
    for nm, v in (("encoder_noise_arcsec", encoder_noise_arcsec), ("gyro_quantization_arcsec", gyro_quantization_arcsec)):
        if v is not None and not (np.isfinite(v) and v >= 0):
            raise InputError(f"{nm} must be a non-negative number of arcsec, got {v!r}")
    kw = {"noise_factor": float(noise_factor), "gyro_quantization_rad": float(gyro_quantization_arcsec) * ARCSEC_TO_RAD}
    kw["encoder_noise_rad"] = None if encoder_noise_arcsec is None else float(encoder_noise_arcsec) * ARCSEC_TO_RAD
    return kw


def _table_scenario(name, *, rng, subranges, hours, span_degC, design, imu_id, noise, errors, rate_hz, effects,
                    effect_scale, curvature, latitude_deg, gravity_mps2, table_valid, encoder_rate_hz, tag,
                    file_stem, cubic_scale=0.0, scale_cubic_scale=0.0, channels=None, noise_factor=1.0,
                    encoder_noise_arcsec=None, gyro_quantization_arcsec=0.0, start_in_motion=False):
    _check_common(hours, rate_hz, effect_scale, effects)
    noise_kw = _noise_keywords(noise_factor=noise_factor, encoder_noise_arcsec=encoder_noise_arcsec,
                               gyro_quantization_arcsec=gyro_quantization_arcsec)
    if not (np.isfinite(cubic_scale) and cubic_scale >= 0):
        raise InputError(f"--cubic-scale must be a non-negative number, got {cubic_scale!r}")
    if not (np.isfinite(scale_cubic_scale) and scale_cubic_scale >= 0):
        raise InputError(f"scale_cubic_scale must be a non-negative number, got {scale_cubic_scale!r}")
    if table_valid not in ("static", "all"):
        raise InputError(f"table_valid must be 'static' or 'all', got {table_valid!r}")
    imu_seed, *seeds = (int(s) for s in rng.integers(0, 2**62, size=1 + len(subranges)))
    imu = draw_imu("navigation", rng=np.random.default_rng(imu_seed), effects=effects, effect_scale=effect_scale,
                   errors=errors, curvature=curvature, cubic_scale=float(cubic_scale),
                   scale_cubic_scale=float(scale_cubic_scale))
    thermal_keywords = {} if channels is None else {"channels": channels[0], "temperature_map": channels[1]}
    azimuth = 0.0
    plans = []
    for i, ((lo, hi), seed) in enumerate(zip(subranges, seeds)):
        if file_stem is None:
            stem = f"sub{i + 1}_{_label(lo)}_{_label(hi)}"
        else:
            stem = file_stem
        width = hi - lo
        span = min(span_degC, width)
        start = lo + 0.5 * (width - span)
        desc = (f"graph-calib simulate {name}: navigation-grade IMU on a two-axis turntable, "
                f"subrange {lo:g}..{hi:g} degC, {hours:g} h at {rate_hz:g} Hz"
                + (f", effects {', '.join(effects)}" if effects else "") + ("" if noise else ", no noise")
                + ("" if errors else ", no errors") + (f"; {tag}" if tag else ""))
        make = partial(
            _make_table_experiment, file_name=f"{stem}.h5", scenario=name, imu=imu, imu_id=imu_id, seed=seed,
            rate_hz=float(rate_hz), duration_s=float(hours) * 3600.0, start_degC=start, span_degC=span,
            design=design, latitude_rad=np.radians(latitude_deg), gravity_mps2=float(gravity_mps2), noise=noise,
            valid=table_valid, encoder_rate_hz=float(encoder_rate_hz), azimuth_rad=azimuth, description=desc,
            tag=tag, start_in_motion=bool(start_in_motion), **noise_kw, **thermal_keywords,
        )
        plans.append(ExperimentPlan(file_name=f"{stem}.h5", make=make,
                                    summary=f"subrange {lo:g}..{hi:g} degC, {hours:g} h"))
    info = {"hours": hours, "rate_hz": rate_hz, "noise": noise, "errors": errors, "effects": list(effects),
            "subranges": [list(s) for s in subranges], "cubic_scale": float(cubic_scale)}
    if scale_cubic_scale:
        info["scale_cubic_scale"] = float(scale_cubic_scale)
    return Simulation(scenario=name, imu_id=imu_id, grade="navigation", plans=tuple(plans), imu=imu, info=info)


def nav_subrange(*, rng, hours=1.5, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                 curvature=True, cubic_scale=0.0, subrange=(20.0, 30.0), span_degC=8.0, latitude_deg=DEFAULT_LATITUDE_DEG,
                 gravity_mps2=DEFAULT_GRAVITY_MPS2, table_valid="static", encoder_rate_hz=10.0, tag="",
                 noise_factor=1.0, encoder_noise_arcsec=None, gyro_quantization_arcsec=0.0, start_in_motion=False):
    """One navigation-grade experiment: 1.5 h at 100 Hz, sensors drifting 8 degC through 20..30 degC.

    15 min static alignment, then rotations at 10-30 deg/s about each instrument
    axis held horizontal, both ways, with 20-40 s static positions between.
    """
    return _table_scenario("nav-subrange", rng=rng, subranges=(tuple(subrange),), hours=hours,
                           span_degC=span_degC, design=NAV_DESIGN, imu_id="SIM-NAV 0001", noise=noise,
                           errors=errors, rate_hz=rate_hz, effects=tuple(effects), effect_scale=effect_scale,
                           curvature=curvature, latitude_deg=latitude_deg, gravity_mps2=gravity_mps2,
                           table_valid=table_valid, encoder_rate_hz=encoder_rate_hz, tag=tag, file_stem=None,
                           cubic_scale=cubic_scale, noise_factor=noise_factor,
                           encoder_noise_arcsec=encoder_noise_arcsec, gyro_quantization_arcsec=gyro_quantization_arcsec,
                           start_in_motion=start_in_motion)


def nav_subrange_short(*, rng, hours=0.3, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                       curvature=True, cubic_scale=0.0, subrange=(20.0, 25.0), span_degC=5.0, latitude_deg=DEFAULT_LATITUDE_DEG,
                       gravity_mps2=DEFAULT_GRAVITY_MPS2, table_valid="static", encoder_rate_hz=10.0, tag="",
                       noise_factor=1.0, encoder_noise_arcsec=None, gyro_quantization_arcsec=0.0,
                       start_in_motion=False, _name="nav-subrange-short", _stem=None):
    """The nav-subrange design in 18 min (3 min alignment, 15-25 s static positions), sensors drifting 5 degC."""
    return _table_scenario(_name, rng=rng, subranges=(tuple(subrange),), hours=hours, span_degC=span_degC,
                           design=SHORT_DESIGN, imu_id="SIM-NAV 0001", noise=noise, errors=errors,
                           rate_hz=rate_hz, effects=tuple(effects), effect_scale=effect_scale, curvature=curvature,
                           latitude_deg=latitude_deg, gravity_mps2=gravity_mps2, table_valid=table_valid,
                           encoder_rate_hz=encoder_rate_hz, tag=tag, file_stem=_stem,
                           cubic_scale=cubic_scale, noise_factor=noise_factor,
                           encoder_noise_arcsec=encoder_noise_arcsec, gyro_quantization_arcsec=gyro_quantization_arcsec,
                           start_in_motion=start_in_motion)


def nav_campaign(*, rng, hours=1.5, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                 curvature=True, cubic_scale=0.0, span_degC=8.0, latitude_deg=DEFAULT_LATITUDE_DEG, gravity_mps2=DEFAULT_GRAVITY_MPS2,
                 table_valid="static", encoder_rate_hz=10.0, tag=""):
    """Six navigation-grade experiments covering -10..+50 degC (one IMU), the nav-subrange design each."""
    return _table_scenario("nav-campaign", rng=rng, subranges=CAMPAIGN_SUBRANGES, hours=hours, span_degC=span_degC,
                           design=NAV_DESIGN, imu_id="SIM-NAV 0001", noise=noise, errors=errors, rate_hz=rate_hz,
                           effects=tuple(effects), effect_scale=effect_scale, curvature=curvature,
                           latitude_deg=latitude_deg, gravity_mps2=gravity_mps2, table_valid=table_valid,
                           encoder_rate_hz=encoder_rate_hz, tag=tag, file_stem=None, cubic_scale=cubic_scale)


def nav_campaign_cubic(*, rng, hours=1.5, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                       cubic_scale=1.0, scale_cubic_scale=1.0, span_degC=8.0, latitude_deg=DEFAULT_LATITUDE_DEG,
                       gravity_mps2=DEFAULT_GRAVITY_MPS2, table_valid="static", encoder_rate_hz=10.0, tag=""):
    """Six navigation-grade experiments over -10..+50 degC whose four temperature families are cubic curves.

    Every bias and scale factor of both triads follows a cubic in its own sensor's temperature (the
    grade's ``*_tc3`` ranges times ``cubic_scale`` and ``scale_cubic_scale``), and each of the six sensors
    has its own temperature channel lagging the chamber with its own time constant
    (:data:`graph_calib.simulation.experiments.SENSOR_CHANNELS`).  The truth files carry the curves
    (``temperature_curves``).
    """
    return _table_scenario("nav-campaign-cubic", rng=rng, subranges=CAMPAIGN_SUBRANGES, hours=hours,
                           span_degC=span_degC, design=NAV_DESIGN, imu_id="SIM-NAV 0002", noise=noise, errors=errors,
                           rate_hz=rate_hz, effects=tuple(effects), effect_scale=effect_scale, curvature=True,
                           latitude_deg=latitude_deg, gravity_mps2=gravity_mps2, table_valid=table_valid,
                           encoder_rate_hz=encoder_rate_hz, tag=tag, file_stem=None, cubic_scale=cubic_scale,
                           scale_cubic_scale=scale_cubic_scale, channels=(SENSOR_CHANNELS, SENSOR_TEMPERATURE_MAP))


def effect_scenario(effect, *, rng, hours=0.3, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                    curvature=True, cubic_scale=0.0, latitude_deg=DEFAULT_LATITUDE_DEG, gravity_mps2=DEFAULT_GRAVITY_MPS2,
                    table_valid="static", encoder_rate_hz=10.0, tag="", noise_factor=1.0, encoder_noise_arcsec=None,
                    gyro_quantization_arcsec=0.0, start_in_motion=False):
    """nav-subrange-short with the further effect ``effect`` switched on (size from ``EFFECT_SIZES``)."""
    return nav_subrange_short(rng=rng, hours=hours, noise=noise, errors=errors, rate_hz=rate_hz,
                              effects=(effect,) + tuple(e for e in effects if e != effect),
                              effect_scale=effect_scale, curvature=curvature, cubic_scale=cubic_scale,
                              latitude_deg=latitude_deg, gravity_mps2=gravity_mps2, table_valid=table_valid, encoder_rate_hz=encoder_rate_hz,
                              tag=tag, noise_factor=noise_factor, encoder_noise_arcsec=encoder_noise_arcsec,
                              gyro_quantization_arcsec=gyro_quantization_arcsec, start_in_motion=start_in_motion,
                              _name=f"effect-{effect}", _stem=f"effect_{effect.replace('.', '_')}")


def consumer_handheld(*, rng, hours=None, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                      n_poses=30, initial_static_s=20.0, hold_s=(3.0, 10.0), turn_s=(1.0, 2.5), translation_m=0.05,
                      latitude_deg=DEFAULT_LATITUDE_DEG, gravity_mps2=DEFAULT_GRAVITY_MPS2, cut=False, pivot_m=0.0,
                      hand_accel_mps2=0.0, tag="", noise_factor=1.0, gyro_noise_factor=1.0):
    """A consumer MEMS IMU turned by hand, no table: 20 s static, then 30 poses of 3-10 s.

    Between poses the hand turns the unit smoothly (1-2.5 s, to a random
    orientation at least 40 deg away) and moves it by a few cm.  The unit warms
    by 2-4 degC after power-on in a room drifting by up to 1 degC/h.  With
    ``hours`` the poses fill that length instead of ``n_poses``.  With ``cut``
    every second turn is cut out (sections cut together, the time stamps left
    continuous) and ``/imu/segment`` marks the pieces; the truth's signals describe
    the session before the cut.  A hand holds no pivot still: ``hand_accel_mps2``
    (rms of the acceleration, m/s^2, at rest and in motion) sways the rotation centre,
    and ``pivot_m`` puts the sensor that far from it (m, a random body direction), so
    that every turn also accelerates the sensor.  ``noise_factor`` multiplies both densities of the grade,
    ``gyro_noise_factor`` the gyro's further (a unit whose gyro is noisy against its accelerometer, as the Xsens
    MTi's: 6.6 gives its 5.7e-4 rad/sqrt(s) beside 2e-3 m/s/sqrt(s)).
    """
    _check_common(hours, rate_hz, effect_scale, effects)
    if not (np.isfinite(gyro_noise_factor) and gyro_noise_factor >= 0):
        raise InputError(f"gyro_noise_factor must be a non-negative number, got {gyro_noise_factor!r}")
    if hours is None and not (isinstance(n_poses, (int, np.integer)) and n_poses >= 1):
        raise InputError(f"n_poses must be a positive integer, got {n_poses!r}")
    exclude = ("mount", "lever_arm", "time_lag.table")
    imu_seed, seed = (int(s) for s in rng.integers(0, 2**62, size=2))
    imu = draw_imu("consumer", rng=np.random.default_rng(imu_seed), effects=effects, effect_scale=effect_scale,
                   errors=errors, curvature=False, exclude=exclude)
    desc = ("graph-calib simulate consumer-handheld: consumer MEMS IMU turned by hand, no table"
            + (", every second turn cut out (/imu/segment)" if cut else "") + ("" if noise else ", no noise") + ("" if errors else ", no errors") + (f"; {tag}" if tag else ""))
    make = partial(
        _make_handheld_experiment, file_name="handheld.h5", scenario="consumer-handheld", imu=imu,
        imu_id="SIM-MEMS 0001", seed=seed, rate_hz=float(rate_hz),
        duration_s=None if hours is None else float(hours) * 3600.0, n_poses=int(n_poses),
        initial_static_s=float(initial_static_s), hold_s=tuple(hold_s), turn_s=tuple(turn_s),
        translation_m=float(translation_m), latitude_rad=np.radians(latitude_deg),
        gravity_mps2=float(gravity_mps2), noise=noise, description=desc, tag=tag, cut=bool(cut),
        pivot_m=float(pivot_m), hand_accel_mps2=float(hand_accel_mps2),
        noise_factor=_noise_keywords(noise_factor=noise_factor)["noise_factor"],
        gyro_noise_factor=float(gyro_noise_factor),
    )
    plan = ExperimentPlan(file_name="handheld.h5", make=make, summary="hand-held poses, no table"
                          + (", every second turn cut out" if cut else ""))
    info = {"hours": hours, "rate_hz": rate_hz, "noise": noise, "errors": errors, "effects": list(effects),
            "cut": bool(cut), "pivot_m": pivot_m, "hand_accel_mps2": hand_accel_mps2}
    return Simulation(scenario="consumer-handheld", imu_id="SIM-MEMS 0001", grade="consumer", plans=(plan,),
                      imu=imu, exclude=exclude, info=info)


def consumer_ferraris(*, rng, hours=None, noise=True, errors=True, rate_hz=100.0, effects=(), effect_scale=1.0,
                      initial_static_s=20.0, latitude_deg=DEFAULT_LATITUDE_DEG, gravity_mps2=DEFAULT_GRAVITY_MPS2,
                      cut=False, pivot_m=0.0, hand_accel_mps2=0.0, tag="", noise_factor=1.0, face_s=10.0, rest_s=5.0,
                      guided=False):
    """A Ferraris-style session of a consumer MEMS IMU by hand, no table (about 2.5 min).

    Six static faces (10 s each, the first 20 s) joined by hand turns, then a
    full turn (360 deg, 3-5 s) about each body axis held horizontal, with 5 s of
    rest before and after (:mod:`graph_calib.simulation.ferraris`).  With ``cut``
    the turns between faces are cut out (the time stamps left continuous):
    every face and every full turn a segment (``/imu/segment``), as sections of a
    session cut together.  ``pivot_m`` and ``hand_accel_mps2`` as for
    ``consumer-handheld``.  The programme has its own length: ``hours`` is refused.
    ``face_s`` and ``rest_s`` (s, a number or a range ``(lo, hi)`` drawn per rest) set the rests on the
    faces and around the full turns; ``initial_static_s=0`` starts the record in motion.  A session as
    a hand makes it: ``face_s=rest_s=(0.5, 1.5), initial_static_s=0, hand_accel_mps2=0.05``
    (:data:`SHORT_REST_FERRARIS`).  ``guided``: each full turn about the axis that is up, slid flat on a level
    surface and back to its start, as imucal's guide has it (:data:`GUIDED_FERRARIS`;
    :mod:`graph_calib.model.guided_turns`).
    """
    if hours is not None:
        raise InputError("consumer-ferraris has a fixed programme (six faces, three full turns): no --hours")
    _check_common(None, rate_hz, effect_scale, effects)
    exclude = ("mount", "lever_arm", "time_lag.table")
    imu_seed, seed = (int(s) for s in rng.integers(0, 2**62, size=2))
    imu = draw_imu("consumer", rng=np.random.default_rng(imu_seed), effects=effects, effect_scale=effect_scale,
                   errors=errors, curvature=False, exclude=exclude)
    desc = ("graph-calib simulate consumer-ferraris: consumer MEMS IMU by hand, six faces and three full turns"
            + (" about the vertical, guided" if guided else "")
            + (", the turns between faces cut out (/imu/segment)" if cut else "")
            + ("" if noise else ", no noise") + ("" if errors else ", no errors") + (f"; {tag}" if tag else ""))
    make = partial(
        _make_handheld_experiment, file_name="ferraris.h5", scenario="consumer-ferraris", imu=imu,
        imu_id="SIM-MEMS 0002", seed=seed, rate_hz=float(rate_hz), duration_s=None, n_poses=0,
        initial_static_s=float(initial_static_s), hold_s=(10.0, 10.0), turn_s=(1.5, 2.5), translation_m=0.0,
        latitude_rad=np.radians(latitude_deg), gravity_mps2=float(gravity_mps2), noise=noise, description=desc,
        tag=tag, cut=bool(cut), pivot_m=float(pivot_m), hand_accel_mps2=float(hand_accel_mps2), program="ferraris",
        noise_factor=_noise_keywords(noise_factor=noise_factor)["noise_factor"],
        face_s=_rest_length(face_s, "face_s"), rest_s=_rest_length(rest_s, "rest_s"), guided=bool(guided),
    )
    plan = ExperimentPlan(file_name="ferraris.h5", make=make, summary="six faces and three full turns by hand"
                          + (", cut together" if cut else ""))
    info = {"rate_hz": rate_hz, "noise": noise, "errors": errors, "effects": list(effects), "cut": bool(cut),
            "pivot_m": pivot_m, "hand_accel_mps2": hand_accel_mps2, "face_s": face_s, "rest_s": rest_s,
            "initial_static_s": initial_static_s, "guided": bool(guided)}
    return Simulation(scenario="consumer-ferraris", imu_id="SIM-MEMS 0002", grade="consumer", plans=(plan,),
                      imu=imu, exclude=exclude, info=info)


#: consumer-ferraris as a hand makes it (issue 22): rests of 0.5-1.5 s on the faces and around the full
#: turns, a swaying hand, the record starting in motion.
SHORT_REST_FERRARIS = {"face_s": (0.5, 1.5), "rest_s": (0.5, 1.5), "initial_static_s": 0.0, "hand_accel_mps2": 0.05}
#: consumer-ferraris as imucal's guide has it: each full turn about the axis that is up, slid flat on a level surface
#: against a guide (:mod:`graph_calib.model.guided_turns`), rests of 3 s as the guide asks, the sensor 5 cm from the
#: turn's axis (its centripetal acceleration tells the turn from a rest, as a real one does).
GUIDED_FERRARIS = {"face_s": 5.0, "rest_s": 3.0, "initial_static_s": 5.0, "guided": True, "pivot_m": 0.1}


def _rest_length(spec, name):
    """A rest length option checked: a positive number of s, or a range ``(lo, hi)`` with ``0 < lo <= hi``."""
    v = np.atleast_1d(np.asarray(spec, dtype=float))
    if v.size not in (1, 2) or not np.all(np.isfinite(v)) or np.any(v <= 0) or (v.size == 2 and v[1] < v[0]):
        raise InputError(f"{name} must be a positive number of s or a range (lo, hi), got {spec!r}")
    return float(v[0]) if v.size == 1 else (float(v[0]), float(v[1]))


@dataclass(frozen=True)
class Scenario:
    """A registry entry: name, one-line summary, ``build(*, rng, **options) -> Simulation``."""

    name: str
    summary: str
    build: Callable

    def options(self):
        """Keyword options the scenario accepts (name -> default)."""
        sig = inspect.signature(self.build)
        return {k: p.default for k, p in sig.parameters.items()
                if p.kind is p.KEYWORD_ONLY and k != "rng" and not k.startswith("_")}


def _registry():
    reg = {
        "nav-subrange": Scenario("nav-subrange", "navigation grade, one 1.5 h experiment at 100 Hz, 20..30 degC",
                                 nav_subrange),
        "nav-subrange-short": Scenario("nav-subrange-short", "the nav-subrange design shortened to 18 min, 5 degC",
                                       nav_subrange_short),
        "nav-campaign": Scenario("nav-campaign", "navigation grade, six 1.5 h experiments over -10..+50 degC",
                                 nav_campaign),
        "nav-campaign-cubic": Scenario("nav-campaign-cubic", "nav-campaign with cubic curves in all four temperature "
                                       "families and a lagging temperature channel per sensor", nav_campaign_cubic),
        "consumer-handheld": Scenario("consumer-handheld", "consumer MEMS turned by hand, no table, ~5 min",
                                      consumer_handheld),
        "consumer-ferraris": Scenario("consumer-ferraris", "consumer MEMS by hand: six faces, three full turns",
                                      consumer_ferraris),
    }
    for e in effects.FURTHER_EFFECTS:
        name = f"effect-{e}"
        build = partial(effect_scenario, e)
        build.__doc__ = effect_scenario.__doc__
        reg[name] = Scenario(name, f"nav-subrange-short with {e} switched on", build)
    return reg


#: Every scenario by name.
SCENARIOS = _registry()


def scenario_names():
    """Names of the known scenarios, in registry order."""
    return list(SCENARIOS)


def get_scenario(name):
    """The :class:`Scenario` called ``name``; :class:`InputError` listing the known ones."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise InputError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}") from None


def simulate(name, *, rng, **options):
    """Build scenario ``name`` with ``options`` (see each scenario's keyword arguments).

    Parameters
    ----------
    name : str
    rng : numpy.random.Generator
        The only source of randomness.
    **options
        Options of the scenario; ``None`` values take the scenario's default.  Common options:
        ``noise`` (False: no sensor, encoder or temperature noise), ``errors`` (False: every truth
        parameter zero), ``hours`` (length of each experiment), ``rate_hz``, ``effects`` (further
        effects of model.md switched on), ``effect_scale`` (multiplies their sizes), ``curvature``
        (False: exactly linear temperature curves), ``cubic_scale`` (a cubic term of the bias curves,
        as real IMUs have: its size relative to the grade's typical one; 0, the default: none), ``latitude_deg``, ``gravity_mps2``,
        ``table_valid`` (``"static"`` or ``"all"``), ``encoder_rate_hz``, ``tag`` (free text for the
        description and the truth file).

    Returns
    -------
    Simulation

    Raises
    ------
    InputError
        Unknown scenario, unknown option, or a bad option value.
    """
    sc = get_scenario(name)
    known = sc.options()
    unknown = [k for k in options if k not in known]
    if unknown:
        raise InputError(f"scenario {name!r} has no option {unknown[0]!r}; options: {', '.join(known)}")
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    opts = {k: v for k, v in options.items() if v is not None}
    return sc.build(rng=rng, **opts)


__all__ = [
    "ExperimentPlan", "Simulation", "Scenario", "SCENARIOS", "scenario_names", "get_scenario", "simulate",
    "nav_subrange", "nav_subrange_short", "nav_campaign", "nav_campaign_cubic", "consumer_handheld", "consumer_ferraris", "effect_scenario",
    "SHORT_REST_FERRARIS", "GUIDED_FERRARIS", "CAMPAIGN_SUBRANGES", "DEFAULT_LATITUDE_DEG", "DEFAULT_GRAVITY_MPS2",
]
