r"""Bench programs: what the turntable, its encoders and the chamber do over time, as a TOML file.

A program (``docs/programs.md``) states a bench run completely: the table's commands (static dwells and
moves of the outer or inner axis by an angle at a peak rate with cosine ramps, from initial axis angles),
which encoder readings may be used (``"static"`` or ``"all"``), the chamber's start temperature and
set-points with their ramp rates, the IMU's sample rate and the encoder rate, the bench's latitude,
gravity and azimuth, and the IMU grade.  Everything is in SI units and radians (degC for temperatures).

:func:`read_program` reads and checks one (every bad value an :class:`~graph_calib.errors.InputError`
naming the file and key), :func:`program_text` writes one, :func:`program_simulation` runs one through
the turntable simulator (:func:`graph_calib.simulation.experiments._make_table_experiment`, the same
builder as the scenarios), and :func:`scenario_program` expresses a scenario's experiment as a program.

The IMU's thermal response is the IMU's, not the bench's: a program's temperatures use the nominal
channels of :data:`graph_calib.simulation.experiments.NAV_CHANNELS` (time constants and self-heating
offsets), so that a program makes the same temperatures whatever the seed.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError
from graph_calib.simulation.experiments import NAV_CHANNELS, _make_table_experiment
from graph_calib.simulation.scenarios import ExperimentPlan, Simulation, _check_common
from graph_calib.simulation.thermal import ThermalModel
from graph_calib.simulation.truth import draw_imu
from graph_calib.simulation.turntable import INNER, OUTER, ProgramBuilder, encoder_axes_f

#: The ``format`` key of a program file.
PROGRAM_FORMAT = "graph-calib-program"
PROGRAM_VERSION = 1

_AXES = {"outer": OUTER, "inner": INNER}


@dataclass(frozen=True)
class Dwell:
    """The table at rest for ``seconds``."""

    seconds: float


@dataclass(frozen=True)
class Move:
    """One table axis (``"outer"`` or ``"inner"``) turned by ``angle_rad`` at peak ``rate_rad_per_s``.

    ``ramp_s``: length of each cosine ramp (rate up, rate down), s.
    """

    axis: str
    angle_rad: float
    rate_rad_per_s: float
    ramp_s: float = 1.0


@dataclass(frozen=True)
class Setpoint:
    """The chamber ramps to ``T_degC`` at ``ramp_degC_per_s``, then holds it for ``hold_s``."""

    T_degC: float
    ramp_degC_per_s: float
    hold_s: float = 0.0


@dataclass(frozen=True)
class BenchProgram:
    """A bench program (module docstring); SI units, radians, degC.

    Attributes
    ----------
    name : str
    steps : tuple of Dwell or Move
    chamber_start_degC : float
        Chamber temperature at the start; the IMU starts in equilibrium with it.
    setpoints : tuple of Setpoint
        After the last one the chamber holds its temperature.
    rate_hz, encoder_rate_hz : float
    encoder_valid : {"static", "all"}
    latitude_rad, gravity_mps2, azimuth_rad : float
    outer0_rad, inner0_rad : float
        Axis angles at the start.
    grade : str
    description : str
    source : str
        File it was read from ("" when built in code).
    """

    name: str
    steps: tuple
    chamber_start_degC: float
    setpoints: tuple = ()
    rate_hz: float = 100.0
    encoder_rate_hz: float = 10.0
    encoder_valid: str = "static"
    latitude_rad: float = math.radians(55.7)
    gravity_mps2: float = 9.8155
    azimuth_rad: float = 0.0
    outer0_rad: float = 0.0
    inner0_rad: float = 0.0
    grade: str = "navigation"
    description: str = ""
    source: str = field(default="", compare=False)

    def table_program(self):
        """The :class:`~graph_calib.simulation.turntable.TableProgram` of the steps (on the sample grid)."""
        b = ProgramBuilder(self.rate_hz, alpha0=self.outer0_rad, beta0=self.inner0_rad)
        for s in self.steps:
            if isinstance(s, Dwell):
                b.dwell(s.seconds)
            else:
                b.move(_AXES[s.axis], s.angle_rad, rate=s.rate_rad_per_s, ramp=s.ramp_s)
        return b.build()

    @property
    def duration_s(self):
        """Length of the program, s (its table commands)."""
        return self.table_program().duration

    def chamber_profile(self):
        """Breakpoints ``(t (P,), T (P,))`` of the chamber, s and degC (piecewise linear, constant after)."""
        t, T = [0.0], [self.chamber_start_degC]
        for sp in self.setpoints:
            dT = sp.T_degC - T[-1]
            if dT != 0.0:
                t.append(t[-1] + abs(dT) / sp.ramp_degC_per_s)
                T.append(sp.T_degC)
            if sp.hold_s > 0:
                t.append(t[-1] + sp.hold_s)
                T.append(sp.T_degC)
        return np.array(t), np.array(T)

    def thermal(self, *, channels=None):
        """The :class:`~graph_calib.simulation.thermal.ThermalModel`: the chamber and the IMU's channels.

        ``channels``: a thermal model whose channel names, time constants and offsets to use (a
        scenario's experiment, to reproduce it); default the nominal :data:`NAV_CHANNELS`.
        """
        tb, Tb = self.chamber_profile()
        if channels is None:
            names = tuple(c[0] for c in NAV_CHANNELS)
            tau = np.array([c[1] for c in NAV_CHANNELS]) * 60.0
            offset = np.array([c[2] for c in NAV_CHANNELS])
        else:
            names = tuple(channels.names)
            tau, offset = np.asarray(channels.tau, dtype=float), np.asarray(channels.offset, dtype=float)
        return ThermalModel(chamber_t=tb, chamber_T=Tb, names=names, tau=tau, offset=offset, initial=Tb[0] + offset)


# ---------------------------------------------------------------------------
# reading and writing
# ---------------------------------------------------------------------------


def _number(table, key, *, path, where, default=None, positive=False, nonneg=False):
    v = table.get(key, default)
    ds = f"{where}.{key}" if where else key
    if v is None:
        raise InputError("missing", path=path, dataset=ds)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise InputError(f"must be a finite number, got {v!r}", path=path, dataset=ds)
    if positive and not v > 0:
        raise InputError(f"must be positive, got {v!r}", path=path, dataset=ds)
    if nonneg and v < 0:
        raise InputError(f"must not be negative, got {v!r}", path=path, dataset=ds)
    return float(v)


def _unknown(table, known, *, path, where):
    extra = sorted(set(table) - set(known))
    if extra:
        raise InputError(f"unknown key {extra[0]!r}; known: {', '.join(known)}", path=path,
                         dataset=f"{where}.{extra[0]}" if where else extra[0])


def parse_program(doc, *, path=""):
    """A :class:`BenchProgram` from a parsed TOML document (``dict``); :class:`InputError` on any bad value."""
    if doc.get("format") != PROGRAM_FORMAT:
        raise InputError(f"not a bench program: format must be {PROGRAM_FORMAT!r}, got {doc.get('format')!r}",
                         path=path, dataset="format")
    version = doc.get("version")
    if version != PROGRAM_VERSION:
        raise InputError(f"version {version!r} is not supported (this graph-calib reads {PROGRAM_VERSION})",
                         path=path, dataset="version")
    _unknown(doc, ("format", "version", "name", "description", "bench", "chamber", "step"), path=path, where="")
    name = doc.get("name", Path(path).stem if path else "program")
    if not isinstance(name, str) or not name or "/" in name:
        raise InputError(f"must be a non-empty file-name-safe string, got {name!r}", path=path, dataset="name")
    bench = doc.get("bench", {})
    bench_keys = ("rate_hz", "encoder_rate_hz", "encoder_valid", "latitude_rad", "gravity_mps2", "azimuth_rad",
                  "outer0_rad", "inner0_rad", "grade")
    _unknown(bench, bench_keys, path=path, where="bench")
    d = BenchProgram(name="x", steps=(), chamber_start_degC=0.0)
    kw = {}
    for key, pos in (("rate_hz", True), ("encoder_rate_hz", True), ("gravity_mps2", True)):
        kw[key] = _number(bench, key, path=path, where="bench", default=getattr(d, key), positive=pos)
    for key in ("latitude_rad", "azimuth_rad", "outer0_rad", "inner0_rad"):
        kw[key] = _number(bench, key, path=path, where="bench", default=getattr(d, key))
    if abs(kw["latitude_rad"]) > math.pi / 2:
        raise InputError(f"must lie within +-pi/2, got {kw['latitude_rad']!r}", path=path, dataset="bench.latitude_rad")
    kw["encoder_valid"] = bench.get("encoder_valid", "static")
    if kw["encoder_valid"] not in ("static", "all"):
        raise InputError(f"must be 'static' or 'all', got {kw['encoder_valid']!r}", path=path,
                         dataset="bench.encoder_valid")
    kw["grade"] = bench.get("grade", "navigation")
    if kw["grade"] != "navigation":
        raise InputError(f"only 'navigation' is simulated on the table, got {kw['grade']!r}", path=path,
                         dataset="bench.grade")
    chamber = doc.get("chamber")
    if not isinstance(chamber, dict):
        raise InputError("missing: the chamber's start_degC (and its set-points)", path=path, dataset="chamber")
    _unknown(chamber, ("start_degC", "setpoint"), path=path, where="chamber")
    start = _number(chamber, "start_degC", path=path, where="chamber")
    setpoints = []
    for i, sp in enumerate(chamber.get("setpoint", [])):
        where = f"chamber.setpoint[{i}]"
        _unknown(sp, ("T_degC", "ramp_degC_per_s", "hold_s"), path=path, where=where)
        setpoints.append(Setpoint(T_degC=_number(sp, "T_degC", path=path, where=where),
                                  ramp_degC_per_s=_number(sp, "ramp_degC_per_s", path=path, where=where,
                                                          positive=True),
                                  hold_s=_number(sp, "hold_s", path=path, where=where, default=0.0, nonneg=True)))
    steps = []
    raw_steps = doc.get("step", [])
    if not isinstance(raw_steps, list) or not raw_steps:
        raise InputError("a program needs at least one [[step]]", path=path, dataset="step")
    for i, st in enumerate(raw_steps):
        where = f"step[{i}]"
        if "dwell_s" in st:
            _unknown(st, ("dwell_s",), path=path, where=where)
            steps.append(Dwell(_number(st, "dwell_s", path=path, where=where, positive=True)))
            continue
        _unknown(st, ("axis", "angle_rad", "rate_rad_per_s", "ramp_s"), path=path, where=where)
        axis = st.get("axis")
        if axis not in _AXES:
            raise InputError(f"a step is a dwell (dwell_s) or a move of axis 'outer' or 'inner', got axis {axis!r}",
                             path=path, dataset=f"{where}.axis")
        steps.append(Move(axis=axis, angle_rad=_number(st, "angle_rad", path=path, where=where),
                          rate_rad_per_s=_number(st, "rate_rad_per_s", path=path, where=where, positive=True),
                          ramp_s=_number(st, "ramp_s", path=path, where=where, default=1.0, positive=True)))
    desc = doc.get("description", "")
    if not isinstance(desc, str):
        raise InputError(f"must be a string, got {desc!r}", path=path, dataset="description")
    return BenchProgram(name=name, steps=tuple(steps), chamber_start_degC=start, setpoints=tuple(setpoints),
                        description=desc, source=str(path), **kw)


def read_toml(path):
    """The parsed TOML document of ``path`` (dict); :class:`InputError` naming the file if it is missing or
    not TOML (bench programs here, design specs in :mod:`graph_calib.design.program_search`)."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such file", path=path)
    try:
        return tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from None


def read_program(path):
    """Read and check a program file (:func:`parse_program`); :class:`InputError` naming the file on any fault."""
    return parse_program(read_toml(path), path=Path(path))


def _f(v):
    return repr(float(v))


def program_text(program):
    """The TOML text of ``program`` (read back by :func:`read_program` to an equal program)."""
    p = program
    q = '"'
    lines = [f"format = {q}{PROGRAM_FORMAT}{q}", f"version = {PROGRAM_VERSION}", f"name = {q}{p.name}{q}"]
    if p.description:
        lines.append("description = " + '"' + p.description.replace("\\", "\\\\").replace('"', '\\"') + '"')
    lines += ["", "[bench]", f"rate_hz = {_f(p.rate_hz)}", f"encoder_rate_hz = {_f(p.encoder_rate_hz)}",
              f"encoder_valid = {q}{p.encoder_valid}{q}",
              f"latitude_rad = {_f(p.latitude_rad)}    # {math.degrees(p.latitude_rad):.4f} deg",
              f"gravity_mps2 = {_f(p.gravity_mps2)}", f"azimuth_rad = {_f(p.azimuth_rad)}",
              f"outer0_rad = {_f(p.outer0_rad)}", f"inner0_rad = {_f(p.inner0_rad)}", f"grade = {q}{p.grade}{q}",
              "", "[chamber]", f"start_degC = {_f(p.chamber_start_degC)}"]
    for sp in p.setpoints:
        lines += ["", "[[chamber.setpoint]]", f"T_degC = {_f(sp.T_degC)}",
                  f"ramp_degC_per_s = {_f(sp.ramp_degC_per_s)}    # {sp.ramp_degC_per_s * 60:.4f} degC/min",
                  f"hold_s = {_f(sp.hold_s)}"]
    for s in p.steps:
        lines.append("")
        lines.append("[[step]]")
        if isinstance(s, Dwell):
            lines.append(f"dwell_s = {_f(s.seconds)}")
        else:
            lines += [f"axis = {q}{s.axis}{q}",
                      f"angle_rad = {_f(s.angle_rad)}    # {math.degrees(s.angle_rad):.3f} deg",
                      f"rate_rad_per_s = {_f(s.rate_rad_per_s)}    # {math.degrees(s.rate_rad_per_s):.3f} deg/s",
                      f"ramp_s = {_f(s.ramp_s)}"]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------
# simulation
# ---------------------------------------------------------------------------


def program_simulation(program, *, rng, noise=True, errors=True, effects=(), effect_scale=1.0, curvature=True,
                       tag="", channels=None):
    """A :class:`~graph_calib.simulation.scenarios.Simulation` of one experiment that runs ``program``.

    The IMU's truth is drawn from ``rng`` as the table scenarios draw it (navigation grade), then the
    experiment's own seed; the program fixes the motion and the temperatures (``channels``: see
    :meth:`BenchProgram.thermal`).
    """
    _check_common(None, program.rate_hz, effect_scale, tuple(effects))
    imu_seed, seed = (int(s) for s in rng.integers(0, 2**62, size=2))
    imu = draw_imu("navigation", rng=np.random.default_rng(imu_seed), effects=tuple(effects),
                   effect_scale=effect_scale, errors=errors, curvature=curvature)
    desc = (f"graph-calib simulate --program {program.name}: navigation-grade IMU on a two-axis turntable, "
            f"{program.duration_s / 3600.0:.3g} h at {program.rate_hz:g} Hz" + ("" if noise else ", no noise")
            + ("" if errors else ", no errors") + (f"; {tag}" if tag else ""))
    file_name = f"{program.name}.h5"
    make = partial(
        _make_table_experiment, file_name=file_name, scenario=f"program:{program.name}", imu=imu,
        imu_id="SIM-NAV 0001", seed=seed, rate_hz=float(program.rate_hz), duration_s=None, start_degC=None,
        span_degC=None, design=None, latitude_rad=program.latitude_rad, gravity_mps2=program.gravity_mps2,
        noise=noise, valid=program.encoder_valid, encoder_rate_hz=program.encoder_rate_hz,
        azimuth_rad=program.azimuth_rad, description=desc, tag=tag, program=program.table_program(),
        thermal=program.thermal(channels=channels),
    )
    plan = ExperimentPlan(file_name=file_name, make=make, summary=f"program {program.name}")
    info = {"program": program.name, "noise": noise, "errors": errors, "effects": list(effects),
            "hours": program.duration_s / 3600.0, "rate_hz": program.rate_hz}
    return Simulation(scenario=f"program:{program.name}", imu_id="SIM-NAV 0001", grade="navigation", plans=(plan,),
                      imu=imu, info=info)


def nominal_experiment(program, *, channels=None):
    """The program's experiment without noise or sensor errors (what :mod:`graph_calib.design.prediction` needs).

    Its table carries the axes the encoders read at each reading (``Table.axes_f``): without noise the
    readings show no scatter, so the model takes the declared encoder noise about the program's own
    two axes (:mod:`graph_calib.model.encoder_noise`), as it would find it in a recorded run's dwells.
    """
    se = program_simulation(program, rng=np.random.default_rng(0), noise=False, errors=False,
                            channels=channels).run()[0]
    exp = se.experiment
    axes = encoder_axes_f(se.signals.motion, exp.table.t)
    return replace(exp, table=replace(exp.table, axes_f=axes))


def steps_of(table_program):
    """The :class:`Dwell` and :class:`Move` steps that rebuild ``table_program`` tick for tick."""
    tp = table_program
    steps = []
    for axis, ramp, cruise, angle in zip(tp.axis, tp.ramp_ticks, tp.cruise_ticks, tp.angle):
        if axis < 0:
            steps.append(Dwell(int(cruise) / tp.rate_hz))
        else:
            total = (int(ramp) + int(cruise)) / tp.rate_hz
            steps.append(Move(axis="outer" if axis == OUTER else "inner", angle_rad=float(angle),
                              rate_rad_per_s=abs(float(angle)) / total, ramp_s=int(ramp) / tp.rate_hz))
    return tuple(steps)


def scenario_program(simulation, *, name, description=""):
    """The program of a table scenario's (first) experiment: its table commands and chamber, exactly.

    The chamber profile becomes set-points at the scenario's ramp rates; the bench (rates, latitude,
    gravity, azimuth, encoder validity) is the scenario's.  The IMU's channels are the nominal ones
    (:meth:`BenchProgram.thermal`), where the scenario draws them within +-10 % per seed.
    """
    se = simulation.plans[0].run()
    kw = simulation._table_keywords()
    tp = se.signals.motion.program
    tb, Tb = np.asarray(se.thermal.chamber_t), np.asarray(se.thermal.chamber_T)
    setpoints = tuple(Setpoint(T_degC=float(Tb[i + 1]),
                               ramp_degC_per_s=max(abs(float(Tb[i + 1] - Tb[i])) / float(tb[i + 1] - tb[i]), 1e-12))
                      for i in range(tb.size - 1))
    return BenchProgram(
        name=name, steps=steps_of(tp), chamber_start_degC=float(Tb[0]), setpoints=setpoints,
        rate_hz=float(kw["rate_hz"]), encoder_rate_hz=float(kw["encoder_rate_hz"]), encoder_valid=kw["valid"],
        latitude_rad=float(kw["latitude_rad"]), gravity_mps2=float(kw["gravity_mps2"]),
        azimuth_rad=float(kw["azimuth_rad"]), outer0_rad=float(tp.angles0[0, 0]), inner0_rad=float(tp.angles0[0, 1]),
        description=description or f"the {simulation.scenario} scenario's experiment as a program",
    )


__all__ = ["PROGRAM_FORMAT", "PROGRAM_VERSION", "Dwell", "Move", "Setpoint", "BenchProgram", "parse_program",
           "read_program", "program_text", "program_simulation", "nominal_experiment", "steps_of",
           "scenario_program"]
