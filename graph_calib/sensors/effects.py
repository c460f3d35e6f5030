r"""The effect registry: one record per parameter of ``model.md``, declared model and further effects.

Everything that depends on which effects exist reads this registry: the calibration-vector layout
and the grades' priors (:mod:`graph_calib.sensors.params`), the sensor error terms
(:mod:`graph_calib.sensors.sensor_model`), what a record without a table or without readings in motion
cannot inform (:mod:`graph_calib.model`), the simulator's effect sizes
(:mod:`graph_calib.simulation.truth`), the diagnosis's candidates and the view its report draws,
and which temperature coefficients the stitching fits over temperature.

Adding a further effect
    One :class:`Effect` record in :data:`REGISTRY` (after the existing ones, so that every seed's
    simulated data stay the same), its sensor term in :mod:`graph_calib.sensors.sensor_model` when the term
    kind is new (a feature and, if it depends on the signal, its derivative), and a test.

Sensor terms
    ``term`` names the feature an element adds to its ``triad``'s measurement (see
    :mod:`graph_calib.sensors.sensor_model`).  Elements map to sensor axes by their names: a one-letter
    element (``x``) is the axis; a two-letter element (``xy``) is row (the sensor axis) and column
    (the signal component the term reads); a scalar parameter adds to all three axes.
    Parameters without a term (``mount``, ``lever_arm``, ``time_lag.table``,
    ``damping.stiffness``) act through the factors of :mod:`graph_calib.model`.
"""

from __future__ import annotations

from dataclasses import dataclass

from graph_calib import constants as c

XYZ = ("x", "y", "z")
NINE = ("xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz")

#: What a parameter needs from the record's table to be informed (``Effect.needs``).
NEEDS_TABLE = "table"                       # a turntable (fixed rotation centre)
NEEDS_VALID_READINGS = "valid readings"     # valid encoder readings
NEEDS_READINGS_IN_MOTION = "readings in motion"   # valid readings taken while the table turns


@dataclass(frozen=True)
class PriorRule:
    """A further effect's prior sigma from a grade's declared ones: ``sigma[base] * factor / divisor``."""

    base: str
    factor: float = 1.0
    divisor: float = 1.0

    def sigma(self, declared_sigmas):
        """The prior sigma given ``{declared parameter: sigma}`` of a grade."""
        return declared_sigmas[self.base] * self.factor / self.divisor


@dataclass(frozen=True)
class Effect:
    """One parameter of the catalogue with everything the project needs to know about it.

    Attributes
    ----------
    name : str
        Flat name, as in ``model.md``.
    elements : tuple of str
        Element names; empty for a scalar parameter.
    unit : str
        SI unit of the value.
    report_unit : str
        Unit shown in reports and printing.
    to_report : float
        Factor from the SI unit into ``report_unit``.
    declared : bool
        Whether the parameter belongs to the declared model (else a further effect).
    triad : str or None
        ``"gyro"`` or ``"accel"``: the measurement its sensor term enters.
    term : str or None
        Sensor-term kind (:mod:`graph_calib.sensors.sensor_model`), None where the factors model it.
    prior : PriorRule or None
        How a grade's prior sigma is set (further effects); None: the grade gives it.
    needs : str or None
        What the record must hold to inform it: :data:`NEEDS_TABLE`, :data:`NEEDS_VALID_READINGS`,
        :data:`NEEDS_READINGS_IN_MOTION`, or None.
    why_needs : str
        The reason, in words, for reports.
    simulation_size : tuple of float or None
        ``(low, high)`` magnitude, SI, the simulator draws when a scenario switches the effect on.
    drawn_when_off : bool
        Whether the simulator draws it also when off (the first effects are, so that switching one
        on does not shift the other draws); effects added later are drawn only when on, so that
        every existing seed's data stay the same.
    positive : bool
        Whether simulated values are positive (time lags), else of random sign (declared or further).
    report_view : tuple of str or None
        ``(driver, triad)``: the residuals against which driver (:mod:`graph_calib.diagnosis`) the
        report shows the effect's signature.
    temperature_of : str or None
        For a temperature coefficient: the parameter it belongs to (``gyro.bias`` for ``gyro.bias_tc``).
    temperature_order : int
        Its power of ``dT`` (1 for ``*_tc``, 2 for ``*_tc2``); 0 for other parameters.
    loop_candidate : bool
        Whether the closed loop of one experiment tests it (:data:`FURTHER_EFFECTS`); False for the higher
        orders of the temperature curves (:data:`CURVE_ORDERS`), which a campaign decides.
    """

    name: str
    elements: tuple
    unit: str
    report_unit: str
    to_report: float
    declared: bool
    triad: str | None = None
    term: str | None = None
    prior: PriorRule | None = None
    needs: str | None = None
    why_needs: str = ""
    simulation_size: tuple | None = None
    drawn_when_off: bool = False
    positive: bool = False
    report_view: tuple | None = None
    temperature_of: str | None = None
    temperature_order: int = 0
    loop_candidate: bool = True

    @property
    def size(self):
        return max(1, len(self.elements))

    def element_names(self):
        if not self.elements:
            return [self.name]
        return [f"{self.name}.{e}" for e in self.elements]


_UG = c.MPS2_TO_UG
_DH = c.RS_TO_DH
_AS = c.RAD_TO_ARCSEC
_PPM = c.TO_PPM
# simulation sizes (SI)
DH = c.DH_TO_RS
AS = c.ARCSEC_TO_RAD
PPM = 1e-6
UG = c.UG_TO_MPS2


def _declared(name, elements, unit, report_unit, to_report, *, triad=None, term=None, needs=None, why_needs="",
              positive=False, temperature_of=None, temperature_order=0):
    return Effect(name, tuple(elements), unit, report_unit, to_report, True, triad=triad, term=term, needs=needs,
                  why_needs=why_needs, positive=positive, temperature_of=temperature_of,
                  temperature_order=temperature_order)


def _further(name, elements, unit, report_unit, to_report, *, triad, term, prior, size, view, needs=None,
             why_needs="", positive=False, drawn_when_off=False, temperature_of=None, temperature_order=0,
             loop_candidate=True):
    return Effect(name, tuple(elements), unit, report_unit, to_report, False, triad=triad, term=term, prior=prior,
                  needs=needs, why_needs=why_needs, simulation_size=size, drawn_when_off=drawn_when_off,
                  positive=positive, report_view=view, temperature_of=temperature_of,
                  temperature_order=temperature_order, loop_candidate=loop_candidate)


#: Every parameter, declared model first, in the canonical order of a calibration vector.
REGISTRY = (
    _declared("gyro.bias", XYZ, "rad/s", "deg/h", _DH, triad="gyro", term="bias"),
    _declared("gyro.bias_tc", XYZ, "rad/s/degC", "deg/h/degC", _DH, triad="gyro", term="bias_tc",
              temperature_of="gyro.bias", temperature_order=1),
    _declared("gyro.scale", XYZ, "1", "ppm", _PPM, triad="gyro", term="scale"),
    _declared("gyro.scale_tc", XYZ, "1/degC", "ppm/degC", _PPM, triad="gyro", term="scale_tc",
              temperature_of="gyro.scale", temperature_order=1),
    _declared("gyro.misalignment", ("xy", "xz", "yx", "yz", "zx", "zy"), "rad", "arcsec", _AS, triad="gyro",
              term="cross"),
    _declared("accel.bias", XYZ, "m/s^2", "micro-g", _UG, triad="accel", term="bias"),
    _declared("accel.bias_tc", XYZ, "m/s^2/degC", "micro-g/degC", _UG, triad="accel", term="bias_tc",
              temperature_of="accel.bias", temperature_order=1),
    _declared("accel.scale", XYZ, "1", "ppm", _PPM, triad="accel", term="scale"),
    _declared("accel.scale_tc", XYZ, "1/degC", "ppm/degC", _PPM, triad="accel", term="scale_tc",
              temperature_of="accel.scale", temperature_order=1),
    _declared("accel.misalignment", ("yx", "zx", "zy"), "rad", "arcsec", _AS, triad="accel", term="cross"),
    _declared("mount", XYZ, "rad", "arcsec", _AS, needs=NEEDS_VALID_READINGS,
              why_needs="the mounting on the faceplate is seen only against the encoders"),
    _declared("lever_arm", XYZ, "m", "mm", 1e3, needs=NEEDS_TABLE,
              why_needs="needs a rotation centre fixed in the level frame"),
    _declared("time_lag.table", (), "s", "ms", 1e3, needs=NEEDS_READINGS_IN_MOTION, positive=True,
              why_needs="a lag changes no reading taken at rest"),
    # further effects
    _further("gyro.bias_tc2", XYZ, "rad/s/degC^2", "deg/h/degC^2", _DH, triad="gyro", term="bias_tc2",
             prior=PriorRule("gyro.bias_tc", divisor=5.0), size=(0.010 * DH, 0.015 * DH),
             view=("temperature", "gyro"), drawn_when_off=True, temperature_of="gyro.bias", temperature_order=2),
    _further("accel.bias_tc2", XYZ, "m/s^2/degC^2", "micro-g/degC^2", _UG, triad="accel", term="bias_tc2",
             prior=PriorRule("accel.bias_tc", divisor=5.0), size=(15 * UG, 25 * UG),
             view=("temperature", "accel"), drawn_when_off=True, temperature_of="accel.bias", temperature_order=2),
    _further("gyro.scale_tc2", XYZ, "1/degC^2", "ppm/degC^2", _PPM, triad="gyro", term="scale_tc2",
             prior=PriorRule("gyro.scale_tc", divisor=5.0), size=(1.0 * PPM, 1.5 * PPM),
             view=("temperature", "gyro"), drawn_when_off=True, temperature_of="gyro.scale", temperature_order=2),
    _further("accel.scale_tc2", XYZ, "1/degC^2", "ppm/degC^2", _PPM, triad="accel", term="scale_tc2",
             prior=PriorRule("accel.scale_tc", divisor=5.0), size=(2.0 * PPM, 3.0 * PPM),
             view=("temperature", "accel"), drawn_when_off=True, temperature_of="accel.scale", temperature_order=2),
    _further("gyro.bias_dtdt", XYZ, "rad/s per degC/s", "deg/h per degC/min", _DH / 60.0, triad="gyro",
             term="bias_dtdt", prior=PriorRule("gyro.bias_tc", factor=600.0), size=(15 * DH, 20 * DH),
             view=("temperature_rate", "gyro"), drawn_when_off=True),
    _further("accel.bias_dtdt", XYZ, "m/s^2 per degC/s", "micro-g per degC/min", _UG / 60.0, triad="accel",
             term="bias_dtdt", prior=PriorRule("accel.bias_tc", factor=600.0), size=(0.015, 0.025),
             view=("temperature_rate", "accel"), drawn_when_off=True),
    _further("gyro.scale_asym", XYZ, "1", "ppm", _PPM, triad="gyro", term="scale_asym",
             prior=PriorRule("gyro.scale"), size=(3 * PPM, 5 * PPM), view=("rate", "gyro"), drawn_when_off=True),
    _further("gyro.g_sensitivity", NINE, "rad/s per m/s^2", "deg/h/g", _DH * c.G0, triad="gyro", term="gsens",
             prior=PriorRule("gyro.bias", divisor=10.0), size=(0.03 * DH / c.G0, 0.06 * DH / c.G0),
             view=("specific_force", "gyro"), drawn_when_off=True),
    _further("accel.nonlinearity", XYZ, "1/(m/s^2)", "micro-g/g^2", _UG * c.G0**2, triad="accel", term="nonlin",
             prior=PriorRule("accel.scale", divisor=10.0), size=(8 * UG / c.G0**2, 15 * UG / c.G0**2),
             view=("specific_force", "accel"), drawn_when_off=True),
    _further("accel.size_effect", ("yx", "yy", "yz", "zx", "zy", "zz"), "m", "mm", 1e3, triad="accel",
             term="size", prior=PriorRule("lever_arm", divisor=2.0), size=(0.005, 0.015),
             view=("rate_size", "accel"), drawn_when_off=True),
    _further("time_lag.accel", (), "s", "ms", 1e3, triad="accel", term="lag", prior=PriorRule("time_lag.table"),
             size=(0.0005, 0.001), view=("rate", "accel"), positive=True, drawn_when_off=True),
    _further("damping.stiffness", NINE, "rad per m/s^2", "arcsec/g", _AS * c.G0, triad=None, term=None,
             prior=PriorRule("mount", divisor=10.0), size=(5 * AS / c.G0, 10 * AS / c.G0),
             view=("specific_force", "gyro"), needs=NEEDS_VALID_READINGS,
             why_needs="needs a turntable: the tilt on the dampers is seen only by the encoders",
             drawn_when_off=True),
    # cubic temperature terms of the biases: the curvature of a real IMU over a wide subrange
    _further("gyro.bias_tc3", XYZ, "rad/s/degC^3", "deg/h/degC^3", _DH, triad="gyro", term="bias_tc3",
             prior=PriorRule("gyro.bias_tc", divisor=2.0), size=(0.02 * DH, 0.03 * DH),
             view=("temperature", "gyro"), temperature_of="gyro.bias", temperature_order=3),
    _further("accel.bias_tc3", XYZ, "m/s^2/degC^3", "micro-g/degC^3", _UG, triad="accel", term="bias_tc3",
             prior=PriorRule("accel.bias_tc", divisor=2.0), size=(1 * UG, 2 * UG),
             view=("temperature", "accel"), temperature_of="accel.bias", temperature_order=3),
    # the higher orders of the four temperature families, up to dT^5: the capacity of a curve over a whole
    # campaign (docs/campaign.md, "Curve capacity"); never a closed-loop candidate of one subrange
    *(_further(f"{base}_tc{k}", XYZ, f"{unit}/degC^{k}", f"{runit}/degC^{k}", to, triad=base.split(".")[0],
               term=f"{base.split('.')[1]}_tc{k}", prior=PriorRule(f"{base}_tc", divisor=10.0 ** (k - 1)), size=None,
               view=("temperature", base.split(".")[0]), temperature_of=base, temperature_order=k,
               loop_candidate=False)
      for k, base, unit, runit, to in (
          (4, "gyro.bias", "rad/s", "deg/h", _DH), (4, "accel.bias", "m/s^2", "micro-g", _UG),
          (5, "gyro.bias", "rad/s", "deg/h", _DH), (5, "accel.bias", "m/s^2", "micro-g", _UG),
          (3, "gyro.scale", "1", "ppm", _PPM), (3, "accel.scale", "1", "ppm", _PPM),
          (4, "gyro.scale", "1", "ppm", _PPM), (4, "accel.scale", "1", "ppm", _PPM),
          (5, "gyro.scale", "1", "ppm", _PPM), (5, "accel.scale", "1", "ppm", _PPM))),
)

#: ``{name: Effect}``.
EFFECTS = {e.name: e for e in REGISTRY}
DECLARED = tuple(e.name for e in REGISTRY if e.declared)
#: The further effects of model.md and the project: the closed loop's candidates (the higher curve orders
#: of :data:`CURVE_ORDERS` are not among them).
FURTHER_EFFECTS = tuple(e.name for e in REGISTRY if not e.declared and e.loop_candidate)
#: Temperature coefficients of order 3 to 5 that only a curve over a whole campaign uses (the joint
#: solver's degrees, a campaign's curvature carried into its subranges); never tested by one subrange's loop.
CURVE_ORDERS = tuple(e.name for e in REGISTRY if not e.declared and not e.loop_candidate)
#: Highest power of ``dT`` of each temperature family: ``{"gyro.bias": 5, ...}``.
MAX_TEMPERATURE_ORDER = {b: max(e.temperature_order for e in REGISTRY if e.temperature_of == b)
                         for b in dict.fromkeys(e.temperature_of for e in REGISTRY if e.temperature_of)}


def effect(name):
    """The :class:`Effect` called ``name``; ``KeyError`` naming the known ones."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise KeyError(f"unknown parameter {name!r}; known: {', '.join(EFFECTS)}") from None


def uninformed(*, has_table, has_valid_readings, readings_in_motion):
    """Parameters a record cannot inform, sorted: what its table (or its absence) leaves out.

    Parameters
    ----------
    has_table : bool
    has_valid_readings : bool
    readings_in_motion : bool
        Whether any valid reading was taken while the table turned.
    """
    lacking = set()
    if not has_table:
        lacking |= {NEEDS_TABLE, NEEDS_VALID_READINGS, NEEDS_READINGS_IN_MOTION}
    elif not has_valid_readings:
        lacking |= {NEEDS_VALID_READINGS, NEEDS_READINGS_IN_MOTION}
    elif not readings_in_motion:
        lacking.add(NEEDS_READINGS_IN_MOTION)
    return tuple(sorted(e.name for e in REGISTRY if e.needs in lacking))


def temperature_family(name):
    """``(base, {order: coefficient name})`` of a parameter: ``gyro.bias_tc`` -> ``('gyro.bias', {1: ..., 2: ...})``."""
    base = EFFECTS[name].temperature_of or name
    return base, {e.temperature_order: e.name for e in REGISTRY if e.temperature_of == base}


def with_lower_orders(names):
    """``names`` with, before each temperature coefficient of order ``k >= 2``, its family's orders below ``k``.

    A curve grows from its low orders: a model holding ``dT^3`` of a family holds ``dT^2`` of it too.  A cubic
    term alone, over a subrange whose temperature is skewed (a ramp's lagging sensor), fits the quadratic
    curvature it is correlated with and leaves the bias and the slope biased: in a 1.5 h campaign a
    subrange's loop adopted ``accel.bias_tc3`` alone and its ``accel.bias.x`` ended 4.5 sigma off.  The
    order a model gains this way keeps its prior (:class:`PriorRule`); it is estimated, not tested.

    Parameters
    ----------
    names : iterable of str
        Parameter names (a name not in :data:`EFFECTS` passes unchanged).

    Returns
    -------
    tuple of str
        Each name once, in the order given, each missing lower order just before the first name needing it.

    Examples
    --------
    >>> with_lower_orders(("accel.bias_tc3", "gyro.g_sensitivity"))
    ('accel.bias_tc2', 'accel.bias_tc3', 'gyro.g_sensitivity')
    """
    out = []
    for name in names:
        e = EFFECTS.get(name)
        if e is not None and e.temperature_order >= 2:
            orders = temperature_family(name)[1]
            out.extend(orders[k] for k in range(2, e.temperature_order) if k in orders and orders[k] not in out)
        if name not in out:
            out.append(name)
    return tuple(out)


__all__ = ["Effect", "PriorRule", "REGISTRY", "EFFECTS", "DECLARED", "FURTHER_EFFECTS", "CURVE_ORDERS",
           "MAX_TEMPERATURE_ORDER", "effect", "uninformed", "with_lower_orders",
           "temperature_family", "NEEDS_TABLE", "NEEDS_VALID_READINGS", "NEEDS_READINGS_IN_MOTION", "XYZ", "NINE"]
