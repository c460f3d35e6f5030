r"""Experiment design: the shortest bench program whose predicted accuracy meets the targets (CasADi, IPOPT).

The criterion (docs/design.md)
------------------------------
What limits a navigation-grade subrange is the gyro bias over temperature: the remaining static gyro
error ``b + b_tc dT`` (:mod:`graph_calib.design.prediction`) must stay under the target (0.01 deg/h at
:data:`graph_calib.design.prediction.CONFIDENCE_SIGMA` sigmas) over the whole temperature range the record
covers; the accelerometers and the scale factors meet theirs with a wide margin in any program that turns
about every axis (the baseline's predicted accelerometer bound is 1 % of its target).

The reduced model
-----------------
The bias is informed in the static dwells, where the encoders (and gravity) hold the attitude while the
gyro integrates its bias and its angle random walk ``N``.  Per gyro axis, a dwell of length ``L`` at mean
sensor temperature offset ``dT`` gives the information

.. math::

    I(L) = \frac{L}{N^2}\Big(1 - \frac{2\ell}{L}\tanh\frac{L}{2\ell}\Big), \qquad \ell = \sigma_e/(N\sqrt{f_e}),

on ``(b, b_tc)`` along ``[1, dT]`` (a random walk seen through white readings of noise ``sigma_e`` at
``f_e``: ``L^3 f_e / (12 sigma_e^2)`` for short dwells, ``L / N^2`` for long ones).  The sensors lag a
chamber that ramps at ``rho`` with their time constants ``tau``: ``T(t) = T_0 + rho (t - tau (1 -
e^{-t/tau}))``, averaged over each dwell in closed form.  With the priors, the 2x2 information per axis
gives ``sigma^2(dT)`` at both ends of the covered range; the constraints are ``k^2 sigma^2 <= target^2``
and a sensor span of at least ``span_degC`` on every gyro channel; the objective is the duration.
An efficiency ``eta`` (information the full model finds per unit of the reduced one) is calibrated by
the full :func:`graph_calib.design.prediction.predict` of each candidate, and the optimisation repeated
until the full prediction meets the targets.

The program
-----------
Discrete structure (enumerated): ``M`` static stations (2 to 4) with one rotation cycle between
consecutive stations; a rotation cycle turns about x, y and z in turn (four quarter turns one way, four
back, one full turn each way, the axis brought horizontal first) at ``rate_dps`` with ``settle_s`` at rest
after every move.  Continuous (CasADi): the station lengths and the chamber ramp rate.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import casadi
import numpy as np

from graph_calib import constants as c
from graph_calib.errors import InputError
from graph_calib.options import CalibrationOptions
from graph_calib.sensors.params import grade as _grade
from graph_calib.design.prediction import CONFIDENCE_SIGMA, predict
from graph_calib.records.problem import build_problem
from graph_calib.simulation.experiments import NAV_CHANNELS
from graph_calib.simulation.program import BenchProgram, Dwell, Move, Setpoint, nominal_experiment, read_toml

#: Gyro channels' time constants of the simulated unit, s (x, y, z): the thermal lag a program must beat.
GYRO_TAU_S = tuple(ch[1] * 60.0 for ch in NAV_CHANNELS[:3])
#: What a thermal chamber reaches, degC: a design whose setpoints leave it is refused.
CHAMBER_RANGE_DEGC = (-70.0, 150.0)
#: Longest program the search predicts in full, s: a target that asks for more is refused naming it (the full
#: prediction of a program years long asked for 202 GiB and ended in an out-of-memory message).
MAX_PROGRAM_S = 12 * 3600.0


@dataclass(frozen=True)
class DesignSpec:
    """What a design must achieve and what the bench allows (SI; ``[spec]`` of a spec TOML file).

    Attributes
    ----------
    grade : str
    gyro_noise : float or None
        rad/sqrt(s); None: the grade's.
    encoder_noise : float or None
        rad; None: the grade's.
    start_degC : float
        Mean sensor temperature at the start (the subrange's low end).
    span_degC : float
        Sensor temperature span the record must cover (every gyro channel).
    max_chamber_ramp_degC_per_s : float
    rate_rad_per_s : float
        Peak table rate of the rotations (at most the bench's limit).
    settle_s : float
        Rest after every move.
    min_station_s : float
        Shortest static station.
    max_overshoot_degC : float
        How far the chamber may go beyond ``span_degC`` above its start (to pull the lagging sensors up).
    gyro_target_radps, accel_target_mps2 : float
    confidence_sigma : float
    stations : tuple of int
        Numbers of static stations tried.
    rate_hz, encoder_rate_hz : float
    """

    grade: str = "navigation"
    gyro_noise: float | None = None
    encoder_noise: float | None = None
    start_degC: float = 21.0
    span_degC: float = 8.0
    max_chamber_ramp_degC_per_s: float = 1.5 / 60.0
    rate_rad_per_s: float = math.radians(30.0)
    settle_s: float = 5.0
    min_station_s: float = 30.0
    max_overshoot_degC: float = 10.0
    gyro_target_radps: float = 0.01 * c.DH_TO_RS
    accel_target_mps2: float = 2e-4
    confidence_sigma: float = CONFIDENCE_SIGMA
    stations: tuple = (2, 3, 4)
    rate_hz: float = 100.0
    encoder_rate_hz: float = 10.0


_SPEC_KEYS = ("grade", "gyro_noise", "encoder_noise", "start_degC", "span_degC", "max_chamber_ramp_degC_per_s",
              "rate_rad_per_s", "settle_s", "min_station_s", "max_overshoot_degC", "gyro_target_radps", "accel_target_mps2",
              "confidence_sigma", "stations", "rate_hz", "encoder_rate_hz")


def read_spec(path):
    """A :class:`DesignSpec` from a TOML file (keys of :class:`DesignSpec` under ``[spec]``); InputError on faults."""
    path = Path(path)
    doc = read_toml(path)
    spec = doc.get("spec")
    if not isinstance(spec, dict) or set(doc) - {"spec"}:
        raise InputError("a design spec holds one [spec] table", path=path)
    kw = {}
    for k, v in spec.items():
        if k not in _SPEC_KEYS:
            raise InputError(f"unknown key {k!r}; known: {', '.join(_SPEC_KEYS)}", path=path, dataset=f"spec.{k}")
        if k == "grade":
            if v != "navigation":
                raise InputError(f"only 'navigation' is designed for, got {v!r}", path=path, dataset="spec.grade")
        elif k == "stations":
            if not (isinstance(v, list) and v and all(isinstance(n, int) and 2 <= n <= 8 for n in v)):
                raise InputError(f"must be a list of integers in 2..8, got {v!r}", path=path, dataset="spec.stations")
            v = tuple(v)
        elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (
                k != "start_degC" and v <= 0):
            raise InputError(f"must be a {'finite' if k == 'start_degC' else 'positive'} number, got {v!r}",
                             path=path, dataset=f"spec.{k}")
        kw[k] = v
    spec = DesignSpec(**kw)
    if spec.encoder_rate_hz > spec.rate_hz:
        raise InputError(f"the table is read at {spec.encoder_rate_hz:g} Hz, faster than the IMU samples "
                         f"({spec.rate_hz:g} Hz): at most rate_hz", path=path, dataset="spec.encoder_rate_hz")
    lo, hi = CHAMBER_RANGE_DEGC
    top = spec.start_degC + spec.span_degC + spec.max_overshoot_degC
    if not (lo <= spec.start_degC and top <= hi):
        raise InputError(f"the chamber would run from {spec.start_degC:g} to {top:g} degC (start, span and overshoot): "
                         f"beyond a thermal chamber's {lo:g}..{hi:g} degC", path=path, dataset="spec.span_degC")
    return spec


# ---------------------------------------------------------------------------
# the program of a design point
# ---------------------------------------------------------------------------


def rotation_cycle(spec):
    """The moves of one rotation cycle (module docstring), each followed by ``settle_s`` at rest.

    Starts and ends with both axes at zero.  Returns a list of steps.
    """
    w, s = spec.rate_rad_per_s, spec.settle_s
    q = math.pi / 2
    steps = []

    def move(axis, angle):
        steps.extend([Move(axis, angle, w), Dwell(s)])

    for _ in range(4):
        move("outer", q)                 # x horizontal on the outer axis: turns about x
    for _ in range(4):
        move("outer", -q)
    move("outer", 4 * q)
    move("outer", -4 * q)
    move("inner", q)                     # -y onto the outer axis: turns about y
    for _ in range(4):
        move("outer", q)
    for _ in range(4):
        move("outer", -q)
    move("outer", 4 * q)
    move("outer", -4 * q)
    move("inner", -q)
    move("outer", q)                     # z horizontal: the inner axis turns about z
    for _ in range(4):
        move("inner", q)
    for _ in range(4):
        move("inner", -q)
    move("inner", 4 * q)
    move("inner", -4 * q)
    move("outer", -q)
    return steps


def cycle_seconds(spec):
    """Length of one rotation cycle on the sample grid, s."""
    p = BenchProgram(name="cycle", steps=tuple(rotation_cycle(spec)), chamber_start_degC=0.0, rate_hz=spec.rate_hz)
    return p.duration_s


def build_program(spec, stations_s, ramp_degC_per_s, *, name="designed", chamber_start_degC=None):
    """The :class:`BenchProgram` of a design point: stations of ``stations_s`` with a rotation cycle between each.

    The chamber holds ``chamber_start_degC`` (default: ``spec.start_degC`` less the channels' mean
    self-heating) through the first station, ramps at ``ramp_degC_per_s`` through the rotation cycles
    and middle stations, and holds where it got to through the last station.
    """
    steps = [Dwell(float(stations_s[0]))]
    for L in stations_s[1:]:
        steps += rotation_cycle(spec)
        steps.append(Dwell(float(L)))
    prog = BenchProgram(name=name, steps=tuple(steps), chamber_start_degC=0.0, rate_hz=spec.rate_hz,
                        encoder_rate_hz=spec.encoder_rate_hz)
    ramp_s = prog.duration_s - float(stations_s[0]) - float(stations_s[-1])
    start = spec.start_degC - _mean_offset() if chamber_start_degC is None else chamber_start_degC
    rho = float(ramp_degC_per_s)
    return replace(prog, chamber_start_degC=float(start),
                   setpoints=(Setpoint(T_degC=float(start), ramp_degC_per_s=rho, hold_s=float(stations_s[0])),
                              Setpoint(T_degC=float(start + rho * ramp_s), ramp_degC_per_s=rho)),
                   description=f"designed by graph-calib design: {len(stations_s)} static stations, "
                               f"{len(stations_s) - 1} rotation cycles, chamber ramp {rho * 60:.3f} degC/min")


def _mean_offset():
    return float(np.mean([ch[2] for ch in NAV_CHANNELS[:4]]))


# ---------------------------------------------------------------------------
# the reduced model and its optimisation
# ---------------------------------------------------------------------------


def _ramp(u, rho, tau):
    """Sensor rise ``u`` s into a chamber ramp of ``rho`` from equilibrium (first-order lag ``tau``)."""
    return rho * (u - tau * (1 - casadi.exp(-u / tau)))


def _ramp_integral(u0, u1, rho, tau):
    """Integral of :func:`_ramp` over ``[u0, u1]``, degC s."""
    def F(u):
        return rho * (u**2 / 2 - tau * u - tau**2 * casadi.exp(-u / tau))
    return F(u1) - F(u0)


def _dwell_information(L, N, ell):
    """Reduced information of a dwell of ``L`` s on a gyro bias (module docstring)."""
    return L / N**2 * (1 - 2 * ell / L * casadi.tanh(L / (2 * ell)))


def temperature_profile(L, rho, *, cycle_s, tau):
    """Sensor temperature rise of the reduced model, as CasADi expressions (or floats).

    The chamber holds during the first station, ramps at ``rho`` through the rotation cycles and the
    middle stations, and holds the temperature it reached during the last station.

    Returns
    -------
    means : list
        Mean rise over each station, degC.
    t_mean : expression
        Mean rise over the whole record (what ``T_ref`` refers to), degC.
    top : expression
        Rise at the end (the highest of the record), degC.
    duration : expression
        s.
    """
    M = len(L)
    means = [0.0 * L[0]]
    total = 0.0 * L[0]
    u = 0.0 * L[0]                                   # time into the ramp
    for i in range(1, M):
        total += _ramp_integral(u, u + cycle_s, rho, tau)
        u = u + cycle_s
        if i < M - 1:
            total += _ramp_integral(u, u + L[i], rho, tau)
            means.append(_ramp_integral(u, u + L[i], rho, tau) / L[i])
            u = u + L[i]
    T1, U1 = _ramp(u, rho, tau), rho * u
    Ll = L[M - 1]
    hold_int = U1 * Ll + (T1 - U1) * tau * (1 - casadi.exp(-Ll / tau))
    means.append(hold_int / Ll)
    total += hold_int
    duration = sum(L[i] for i in range(M)) + (M - 1) * cycle_s
    top = U1 + (T1 - U1) * casadi.exp(-Ll / tau)
    return means, total / duration, top, duration


@dataclass(frozen=True)
class ReducedSolution:
    """The reduced model's optimum for one structure."""

    stations_s: tuple
    ramp_degC_per_s: float
    duration_s: float
    reduced_sigma_radps: tuple      # largest reduced one sigma per gyro axis over the covered range
    status: str


def optimise(spec, n_stations, *, eta=1.0):
    """Shortest station lengths and ramp rate of the reduced model for ``n_stations`` (CasADi Opti, IPOPT)."""
    g = _grade(spec.grade)
    N = spec.gyro_noise or g.gyro_noise
    sig_e = spec.encoder_noise or g.encoder_noise
    ell = sig_e / (N * math.sqrt(spec.encoder_rate_hz))
    prior_b, prior_tc = g.prior_sigma["gyro.bias"], g.prior_sigma["gyro.bias_tc"]
    Tc = cycle_seconds(spec)
    k = spec.confidence_sigma
    opti = casadi.Opti()
    L = opti.variable(n_stations)
    rho = opti.variable()
    Ls = [L[i] for i in range(n_stations)]
    worst = []
    for tau in GYRO_TAU_S:
        means, t_ref, top, D = temperature_profile(Ls, rho, cycle_s=Tc, tau=tau)
        H = casadi.DM([[1 / prior_b**2, 0], [0, 1 / prior_tc**2]])
        for i in range(n_stations):
            v = casadi.vertcat(1, means[i] - t_ref)
            H = H + eta * _dwell_information(Ls[i], N, ell) * (v @ v.T)
        det = H[0, 0] * H[1, 1] - H[0, 1] ** 2
        for dT_end in (-t_ref, top - t_ref):
            var = (H[1, 1] - 2 * H[0, 1] * dT_end + H[0, 0] * dT_end**2) / det
            opti.subject_to(k**2 * var / spec.gyro_target_radps**2 <= 1)   # scaled: IPOPT's tolerances are absolute
            worst.append(var)
        opti.subject_to(top >= spec.span_degC)
    # the chamber's own excursion: at most span + overshoot above the start
    ramp_s = (n_stations - 1) * Tc + sum(Ls[i] for i in range(1, n_stations - 1))
    opti.subject_to(rho * ramp_s <= spec.span_degC + spec.max_overshoot_degC)
    opti.subject_to(L >= spec.min_station_s)
    opti.subject_to(opti.bounded(1e-5, rho, spec.max_chamber_ramp_degC_per_s))
    opti.minimize(D / 3600.0)
    opti.set_initial(L, 1200.0 / n_stations + spec.min_station_s)
    opti.set_initial(rho, spec.max_chamber_ramp_degC_per_s / 2)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "max_iter": 500, "tol": 1e-10,
                                                 "sb": "yes"})
    try:
        sol = opti.solve()
        status = "solved"
    except RuntimeError:
        sol = opti.debug
        status = opti.return_status()
    Lv = tuple(float(v) for v in np.ravel(sol.value(L)))
    var = [float(sol.value(w)) for w in worst]
    per_axis = tuple(math.sqrt(max(var[2 * i], var[2 * i + 1])) for i in range(3))
    return ReducedSolution(stations_s=Lv, ramp_degC_per_s=float(sol.value(rho)), duration_s=float(sol.value(D)),
                           reduced_sigma_radps=per_axis, status=status)


# ---------------------------------------------------------------------------
# the design loop: reduced optimum, full prediction, efficiency, again
# ---------------------------------------------------------------------------


def full_prediction(program, spec):
    """The full :func:`graph_calib.design.prediction.predict` of ``program`` with the spec's noise (problem, prediction)."""
    exp = nominal_experiment(program)
    opts = CalibrationOptions()
    opts = replace(opts, model=replace(opts.model, grade=spec.grade, gyro_noise=spec.gyro_noise,
                                       encoder_noise=spec.encoder_noise))
    problem = build_problem(exp, options=opts)
    return problem, predict(problem, confidence_sigma=spec.confidence_sigma,
                            targets=(spec.gyro_target_radps, spec.accel_target_mps2))


def _meets(bound_summary):
    return bool(bound_summary["meets"]["all"])


@dataclass(frozen=True)
class Candidate:
    """One structure's verified design."""

    n_stations: int
    program: BenchProgram
    reduced: ReducedSolution
    eta: float
    bound: dict                      # full prediction's remaining-error summary
    history: tuple                   # (eta, reduced duration s, full largest gyro bound rad/s) per round
    problem: object = field(repr=False, default=None)
    prediction: object = field(repr=False, default=None)

    @property
    def meets(self):
        return _meets(self.bound)


def design_structure(spec, n_stations, *, rounds=6, progress=None):
    """Optimise one structure, verify it with the full prediction, recalibrate ``eta``, again.

    ``eta`` scales the reduced information to what the full model finds on the last candidate (the
    variance goes as ``1 / eta``), aiming at 99 % of the target; the rounds stop once a candidate meets
    the targets within 3 % of them, or meets them while another constraint (the temperature span, the
    shortest station) holds the reduced optimum.  The shortest candidate that meets them is kept.
    """
    eta = 1.0
    history = []
    best = last = None
    for r in range(rounds):
        red = optimise(spec, n_stations, eta=eta)
        if red.duration_s > MAX_PROGRAM_S:
            raise InputError(f"the targets ask for a program of {red.duration_s / 3600:.3g} h ({n_stations} stations, "
                             f"the reduced model), beyond the {MAX_PROGRAM_S / 3600:g} h this search predicts: relax "
                             f"the gyro target ({spec.gyro_target_radps * c.RS_TO_DH:.3g} deg/h) or the accelerometer "
                             f"target ({spec.accel_target_mps2:.3g} m/s^2)", dataset="spec.gyro_target_radps")
        prog = build_program(spec, red.stations_s, red.ramp_degC_per_s)
        problem, pred = full_prediction(prog, spec)
        b = pred.bound.summary()
        g_bound = max(b["gyro_radps"]["bound"])
        history.append((eta, red.duration_s, g_bound))
        if progress is not None:
            progress(f"  {n_stations} stations, round {r + 1}: eta {eta:.3f}, {red.duration_s / 60:.1f} min, "
                     f"full-model gyro bound {g_bound * c.RS_TO_DH:.4f} deg/h ({red.status})")
        last = Candidate(n_stations, prog, red, eta, b, (), problem, pred)
        if _meets(b) and (best is None or prog.duration_s < best.program.duration_s):
            best = last
        inactive = spec.confidence_sigma * max(red.reduced_sigma_radps) < 0.97 * spec.gyro_target_radps
        if _meets(b) and (g_bound > 0.97 * spec.gyro_target_radps or inactive):
            break                           # on the target, or held by another constraint (eta cannot help)
        eta *= 0.99 * (spec.gyro_target_radps / g_bound) ** 2
    return replace(best or last, history=tuple(history))


@dataclass(frozen=True)
class Design:
    """Outcome of :func:`design`."""

    best: Candidate
    candidates: tuple
    baseline_program: BenchProgram | None
    baseline_prediction: object
    seconds: float


def design(spec=DesignSpec(), *, baseline=None, progress=None):
    """The shortest verified program over the structures of ``spec.stations`` (module docstring).

    ``baseline``: a :class:`BenchProgram` to predict beside it (``data/programs/nav-subrange.toml``).
    """
    t0 = time.perf_counter()
    cands = []
    for m in spec.stations:
        if progress is not None:
            progress(f"structure: {m} static stations, {m - 1} rotation cycles")
        cands.append(design_structure(spec, m, progress=progress))
    ok = [cd for cd in cands if cd.meets]
    best = min(ok or cands, key=lambda cd: cd.program.duration_s)
    base_pred = None
    if baseline is not None:
        base_pred = full_prediction(baseline, spec)
    return Design(best=best, candidates=tuple(cands), baseline_program=baseline, baseline_prediction=base_pred,
                  seconds=time.perf_counter() - t0)


__all__ = ["DesignSpec", "read_spec", "rotation_cycle", "cycle_seconds", "build_program", "optimise",
           "full_prediction", "design_structure", "design", "Design", "Candidate", "ReducedSolution", "GYRO_TAU_S"]


def design_document(result, spec):
    """``design.json``: duration, targets and whether they are met, the structures tried, the reduced model's
    agreement with the full one, the baseline with its duration and prediction."""
    best = result.best
    b = best.bound
    red_sigma = list(best.reduced.reduced_sigma_radps)
    full_sigma = b["gyro_radps"]["largest_sigma"]
    doc = {
        "format": "graph-calib-design", "version": 1,
        "spec": {k: (list(v) if isinstance(v, tuple) else v) for k, v in spec.__dict__.items()},
        "duration_s": best.program.duration_s,
        "targets": {"gyro_radps": spec.gyro_target_radps, "accel_mps2": spec.accel_target_mps2,
                    "confidence_sigma": spec.confidence_sigma},
        "targets_met": best.meets,
        "predicted_bound": b,
        "structure": {"stations": best.n_stations, "rotation_cycles": best.n_stations - 1,
                      "stations_s": list(best.reduced.stations_s), "cycle_s": cycle_seconds(spec),
                      "chamber_ramp_degC_per_s": best.reduced.ramp_degC_per_s},
        "reduced_model": {
            "eta": best.eta, "solver": "casadi " + casadi.__version__ + " / ipopt",
            "largest_gyro_sigma_radps": {"reduced_at_eta": red_sigma, "full": full_sigma},
            "rounds": [{"eta": e, "reduced_duration_s": d, "full_gyro_bound_radps": g} for e, d, g in best.history],
        },
        "candidates": [{"stations": cd.n_stations, "duration_s": cd.program.duration_s, "meets": cd.meets,
                        "gyro_bound_radps": max(cd.bound["gyro_radps"]["bound"]), "eta": cd.eta}
                       for cd in result.candidates],
        "seconds": result.seconds,
    }
    if result.baseline_program is not None:
        bp = result.baseline_prediction[1].bound.summary()
        doc["baseline"] = {"name": result.baseline_program.name, "duration_s": result.baseline_program.duration_s,
                           "predicted_bound": bp, "targets_met": bool(bp["meets"]["all"])}
        doc["duration_ratio_to_baseline"] = best.program.duration_s / result.baseline_program.duration_s
    return doc


__all__ += ["design_document"]
