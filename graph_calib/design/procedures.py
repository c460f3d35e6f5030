r"""Campaign procedures: how a whole temperature range is calibrated, as bench programs per experiment.

A *procedure* is what a comparison (:mod:`graph_calib.design.comparison`) sets against another: the
experiments a campaign runs over the temperature range, how long each is recorded, what waits between
them, and which model each experiment is calibrated with.  Three kinds:

``steps``
    The traditional procedure: the chamber steps to each of ``temperatures_degC`` and holds; before every
    step but the first the IMU is soaked for ``soak_s`` (not recorded, long enough for the sensors to
    settle: the simulated step is *perfectly* constant), then ``L`` seconds are recorded at constant
    temperature.  The temperature coefficients are not observable at constant temperature and are left
    out of the model (``*.bias_tc``, ``*.scale_tc``).  Duration ``n L + (n - 1) soak_s``.
``ramp``
    The continuous procedure: one experiment per subrange of ``subranges_degC``, the chamber ramping all
    the time (:func:`graph_calib.simulation.thermal.ramp_chamber`, the scenarios' three-part ramp) so that
    the sensors drift by ``span_degC`` across the subrange's middle; values and temperature coefficients
    estimated.  Duration ``n L``.
``program``
    A designed (or any) bench program run once per subrange, its chamber profile shifted so that the
    sensors' temperatures sit in the middle of each subrange; one length, the program's own.  Duration
    ``n`` times the program's length.

``steps`` and ``ramp`` may discard ``discarded_s`` seconds at the start of every experiment (a warm-up or
settling after the soak, a start the lab does not use): the duration counts the whole recorded length
``L``, the prediction only the ``L - discarded_s`` that follow.

``steps`` and ``ramp`` sweep the recorded length per experiment over ``lengths_s``; their turntable
motion is the navigation rotation design (:func:`graph_calib.simulation.design.rotation_program`) of
that length, drawn with ``seed``.  Every experiment of one length runs the same table motion and the
same chamber shape shifted in temperature, so one prediction of the shared model serves them all (the
model's Jacobians depend on temperature only through ``T - T_ref``).

The file (TOML)::

    format = "graph-calib-procedure"
    version = 1
    name = "steps-7"                       # file-name safe
    description = "free text"
    kind = "steps"                         # "steps", "ramp" or "program"
    temperatures_degC = [-10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0]   # steps
    soak_s = 9000.0                        # steps: soak before each step after the first
    subranges_degC = [[-10.0, 0.0], [0.0, 10.0]]                    # ramp, program
    span_degC = 8.0                        # ramp: the sensors' drift per subrange
    lengths_s = [900.0, 1800.0, 3600.0]    # steps, ramp: recorded seconds per experiment
    discarded_s = 0.0                      # steps, ramp: seconds of each that the calibration does not use
    seed = 1                               # steps, ramp: the rotation design's draws
    program = "designed-nav-subrange.toml" # program: a bench program, relative to this file
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from graph_calib.errors import InputError
from graph_calib.simulation.design import NAV_DESIGN, rotation_program
from graph_calib.simulation.experiments import NAV_CHANNELS, NAV_TEMPERATURE_MAP
from graph_calib.simulation.program import BenchProgram, Setpoint, read_program, read_toml, steps_of
from graph_calib.simulation.thermal import ramp_chamber

PROCEDURE_FORMAT = "graph-calib-procedure"
PROCEDURE_VERSION = 1
KINDS = ("steps", "ramp", "program")

#: Parameters a constant-temperature step cannot inform (its model leaves them out).
STEP_EXCLUDED = ("gyro.bias_tc", "gyro.scale_tc", "accel.bias_tc", "accel.scale_tc")

_KEYS = {
    "steps": ("temperatures_degC", "soak_s", "lengths_s", "discarded_s", "seed"),
    "ramp": ("subranges_degC", "span_degC", "lengths_s", "discarded_s", "seed"),
    "program": ("subranges_degC", "program"),
}


@dataclass(frozen=True)
class Experiment:
    """One experiment of a procedure: its label and its temperature shift from the procedure's base program."""

    label: str
    shift_degC: float


@dataclass(frozen=True)
class Procedure:
    """A campaign procedure (module docstring).  SI units; temperatures degC.

    Attributes
    ----------
    name, kind, description : str
    temperatures_degC : tuple of float
        ``steps``: the chamber temperature of each step.
    subranges_degC : tuple of (float, float)
        ``ramp`` and ``program``.
    soak_s : float
        ``steps``: the soak before each step after the first.
    span_degC : float
        ``ramp``: the sensors' drift across each subrange.
    lengths_s : tuple of float
        ``steps`` and ``ramp``: recorded seconds per experiment, one campaign per length.
    discarded_s : float
        ``steps`` and ``ramp``: seconds at the start of each experiment that the calibration does not use
        (counted in the duration, not in the data).
    seed : int
        The rotation design's draws.
    program : BenchProgram or None
        ``program``: the program run in every subrange.
    source : str
    """

    name: str
    kind: str
    description: str = ""
    temperatures_degC: tuple = ()
    subranges_degC: tuple = ()
    soak_s: float = 0.0
    span_degC: float = 8.0
    lengths_s: tuple = ()
    discarded_s: float = 0.0
    seed: int = 1
    program: BenchProgram | None = None
    source: str = ""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise InputError(f"kind must be one of {', '.join(KINDS)}, got {self.kind!r}", path=self.source or None,
                             dataset="kind")

    @property
    def n_experiments(self):
        return len(self.temperatures_degC) if self.kind == "steps" else len(self.subranges_degC)

    @property
    def exclude(self):
        """Parameters left out of each experiment's model."""
        return STEP_EXCLUDED if self.kind == "steps" else ()

    def lengths(self):
        """Recorded seconds per experiment of each campaign of the procedure."""
        return (float(self.program.duration_s),) if self.kind == "program" else tuple(self.lengths_s)

    def duration_s(self, length_s, *, soak_s=None):
        """Campaign duration with ``length_s`` recorded per experiment (``soak_s`` overrides the procedure's)."""
        n = self.n_experiments
        if self.kind == "steps":
            w = self.soak_s if soak_s is None else float(soak_s)
            return n * float(length_s) + (n - 1) * w
        return n * float(length_s)

    def base_program(self, length_s, *, rate_hz=None):
        """The bench program of one experiment of ``length_s`` seconds before its temperature shift: the
        ``length_s - discarded_s`` seconds the calibration uses.

        ``rate_hz``: the IMU sample rate (default: 100 Hz, a ``program`` its own).
        """
        if self.kind == "program":
            return self.program if rate_hz is None else replace(self.program, rate_hz=float(rate_hz))
        rate_hz = 100.0 if rate_hz is None else rate_hz
        length_s = float(length_s) - self.discarded_s
        tp = rotation_program(float(rate_hz), float(length_s), rng=np.random.default_rng(self.seed),
                              design=NAV_DESIGN)
        steps = steps_of(tp)
        if self.kind == "steps":
            return BenchProgram(name=f"{self.name}-{length_s:g}s", steps=steps, chamber_start_degC=0.0,
                                rate_hz=float(rate_hz), description=f"{self.name}: one constant-temperature step")
        names = tuple(ch[0] for ch in NAV_CHANNELS)
        tau = np.array([ch[1] for ch in NAV_CHANNELS]) * 60.0
        offset = np.array([ch[2] for ch in NAV_CHANNELS])
        th = ramp_chamber(duration=float(length_s), start_degC=0.0, span_degC=self.span_degC, names=names, tau=tau,
                          offset=offset, temperature_map=NAV_TEMPERATURE_MAP)
        tb, Tb = np.asarray(th.chamber_t), np.asarray(th.chamber_T)
        sps = tuple(Setpoint(T_degC=float(Tb[i + 1]),
                             ramp_degC_per_s=max(abs(float(Tb[i + 1] - Tb[i])) / float(tb[i + 1] - tb[i]), 1e-12))
                    for i in range(tb.size - 1))
        return BenchProgram(name=f"{self.name}-{length_s:g}s", steps=steps, chamber_start_degC=float(Tb[0]),
                            setpoints=sps, rate_hz=float(rate_hz), description=f"{self.name}: one ramped subrange")

    def experiments(self, base_sensor_mid_degC):
        """The experiments, each a shift of the base program's temperatures.

        ``base_sensor_mid_degC``: the middle of the base record's mean sensor temperature range (what a
        ``ramp`` or ``program`` experiment centres on its subrange); a step's chamber temperature is its
        shift.
        """
        if self.kind == "steps":
            return tuple(Experiment(f"step_{T:g}", float(T)) for T in self.temperatures_degC)
        return tuple(Experiment(f"sub_{lo:g}_{hi:g}", 0.5 * (lo + hi) - float(base_sensor_mid_degC))
                     for lo, hi in self.subranges_degC)

    def to_dict(self):
        out = {"name": self.name, "kind": self.kind, "description": self.description,
               "experiments": self.n_experiments, "lengths_s": list(self.lengths())}
        if self.kind == "steps":
            out.update(temperatures_degC=list(self.temperatures_degC), soak_s=self.soak_s)
        if self.kind in ("steps", "ramp"):
            out["discarded_s"] = self.discarded_s
        if self.kind != "steps":
            out["subranges_degC"] = [list(s) for s in self.subranges_degC]
        if self.kind == "ramp":
            out["span_degC"] = self.span_degC
        if self.kind == "program":
            out["program"] = self.program.name
        return out


def _numbers(doc, key, *, path, positive=False):
    v = doc.get(key)
    if not isinstance(v, list) or not v:
        raise InputError("must be a non-empty list of numbers", path=path, dataset=key)
    out = []
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or (positive and x <= 0):
            raise InputError(f"must be a {'positive' if positive else 'finite'} number, got {x!r}", path=path,
                             dataset=f"{key}[{i}]")
        out.append(float(x))
    return tuple(out)


def _number(doc, key, *, path, default, nonneg=True):
    v = doc.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (nonneg and v < 0):
        raise InputError(f"must be a {'non-negative' if nonneg else 'finite'} number, got {v!r}", path=path,
                         dataset=key)
    return float(v)


def parse_procedure(doc, *, path=""):
    """A :class:`Procedure` from a parsed TOML document; :class:`InputError` naming the file and key."""
    path = path or None
    if doc.get("format") != PROCEDURE_FORMAT:
        raise InputError(f"not a procedure: format must be {PROCEDURE_FORMAT!r}, got {doc.get('format')!r}",
                         path=path, dataset="format")
    if doc.get("version") != PROCEDURE_VERSION:
        raise InputError(f"version {doc.get('version')!r} is not supported (this graph-calib reads "
                         f"{PROCEDURE_VERSION})", path=path, dataset="version")
    kind = doc.get("kind")
    if kind not in KINDS:
        raise InputError(f"must be one of {', '.join(KINDS)}, got {kind!r}", path=path, dataset="kind")
    known = ("format", "version", "name", "description", "kind") + _KEYS[kind]
    extra = sorted(set(doc) - set(known))
    if extra:
        raise InputError(f"unknown key for a {kind!r} procedure; known: {', '.join(known)}", path=path,
                         dataset=extra[0])
    name = doc.get("name", Path(path).stem if path else "procedure")
    if not isinstance(name, str) or not name or "/" in name:
        raise InputError(f"must be a non-empty file-name-safe string, got {name!r}", path=path, dataset="name")
    desc = doc.get("description", "")
    if not isinstance(desc, str):
        raise InputError(f"must be a string, got {desc!r}", path=path, dataset="description")
    kw = {"name": name, "kind": kind, "description": desc, "source": str(path or "")}
    if kind == "steps":
        kw["temperatures_degC"] = _numbers(doc, "temperatures_degC", path=path)
        if len(kw["temperatures_degC"]) < 2:
            raise InputError("a step procedure needs at least two temperatures", path=path,
                             dataset="temperatures_degC")
        kw["soak_s"] = _number(doc, "soak_s", path=path, default=None)
        named = [f"{T:g}" for T in kw["temperatures_degC"]]       # each step is the experiment step_<T>
        twice = sorted({n for n in named if named.count(n) > 1}, key=float)
        if twice:
            raise InputError(f"each step is one experiment: {', '.join(twice)} degC appear(s) more than once",
                             path=path, dataset="temperatures_degC")
    else:
        subs = doc.get("subranges_degC")
        if not isinstance(subs, list) or not subs:
            raise InputError("must be a non-empty list of [low, high] pairs", path=path, dataset="subranges_degC")
        pairs = []
        for i, s in enumerate(subs):
            ok = (isinstance(s, list) and len(s) == 2
                  and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in s))
            if not ok or not s[1] > s[0]:
                raise InputError(f"must be [low, high] with low < high, got {s!r}", path=path,
                                 dataset=f"subranges_degC[{i}]")
            pairs.append((float(s[0]), float(s[1])))
            if f"{s[0]:g}_{s[1]:g}" in (f"{lo:g}_{hi:g}" for lo, hi in pairs[:-1]):   # the experiment sub_<lo>_<hi>
                raise InputError(f"each subrange is one experiment: {s!r} appears more than once", path=path,
                                 dataset=f"subranges_degC[{i}]")
        kw["subranges_degC"] = tuple(pairs)
    if kind in ("steps", "ramp"):
        kw["lengths_s"] = _numbers(doc, "lengths_s", path=path, positive=True)
        kw["discarded_s"] = _number(doc, "discarded_s", path=path, default=0.0)
        if any(L - kw["discarded_s"] < 300.0 for L in kw["lengths_s"]):
            what = "" if not kw["discarded_s"] else f" after the {kw['discarded_s']:g} s discarded (discarded_s)"
            raise InputError(f"every recorded length must be at least 300 s{what} (the alignment and one rotation "
                             "cycle)", path=path, dataset="lengths_s")
        seed = doc.get("seed", 1)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise InputError(f"must be a non-negative integer, got {seed!r}", path=path, dataset="seed")
        kw["seed"] = seed
    if kind == "ramp":
        kw["span_degC"] = _number(doc, "span_degC", path=path, default=8.0)
        widths = [hi - lo for lo, hi in kw["subranges_degC"]]
        if not 0 < kw["span_degC"] <= min(widths):
            raise InputError(f"must be positive and at most the narrowest subrange ({min(widths):g} degC), got "
                             f"{kw['span_degC']!r}", path=path, dataset="span_degC")
    if kind == "program":
        prog = doc.get("program")
        if not isinstance(prog, str) or not prog:
            raise InputError("must name a bench program file (TOML, docs/programs.md)", path=path, dataset="program")
        ppath = Path(prog) if Path(prog).is_absolute() or not path else Path(path).parent / prog
        kw["program"] = read_program(ppath)
    return Procedure(**kw)


def read_procedure(path):
    """Read and check a procedure file; :class:`InputError` naming the file and the key on any fault."""
    return parse_procedure(read_toml(path), path=Path(path))


def with_soak(procedure, soak_s):
    """The same procedure with another soak (``steps`` only; other kinds returned as they are)."""
    return replace(procedure, soak_s=float(soak_s)) if procedure.kind == "steps" else procedure


__all__ = ["PROCEDURE_FORMAT", "PROCEDURE_VERSION", "KINDS", "STEP_EXCLUDED", "Experiment", "Procedure",
           "parse_procedure", "read_procedure", "with_soak"]
