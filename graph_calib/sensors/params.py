"""The layout of a calibration vector, and the IMU grades (priors and noise).

The parameters themselves (flat names, elements, units, what each needs) are the effect
registry, :mod:`graph_calib.sensors.effects`.  A :class:`Layout` fixes which parameters a solver
estimates and where each sits in the flat calibration vector ``x``; it is the one
name-to-slice registry that the model, every solver and the files use.

Examples
--------
>>> layout = Layout.declared()
>>> layout.slice("gyro.bias")
slice(0, 3, None)
>>> layout.element_names()[:2]
['gyro.bias.x', 'gyro.bias.y']
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph_calib import constants as c
from graph_calib.sensors.effects import DECLARED, EFFECTS, REGISTRY


def split_element_name(flat):
    """Split ``'gyro.misalignment.zx'`` into ``('gyro.misalignment', 'zx')``; a scalar gives ``(name, None)``."""
    if flat in EFFECTS and not EFFECTS[flat].elements:
        return flat, None
    name, _, element = flat.rpartition(".")
    if name not in EFFECTS or element not in EFFECTS[name].elements:
        raise KeyError(f"unknown parameter element {flat!r}")
    return name, element


#: The six sensors whose temperatures the record holds, in its column order.
SENSORS = ("gyro.x", "gyro.y", "gyro.z", "accel.x", "accel.y", "accel.z")


def sensor_of(element):
    """Index (0..5, :data:`SENSORS`) of the sensor whose temperature an element follows, or None.

    ``gyro.*`` and ``accel.*`` elements belong to the axis their element name
    starts with (``gyro.misalignment.zx`` -> gyro z); other parameters (mount,
    lever arm, time lags) have no sensor.

    >>> sensor_of("accel.bias.y"), sensor_of("gyro.misalignment.zx"), sensor_of("mount.x")
    (4, 2, None)
    """
    name, el = split_element_name(element)
    triad = name.split(".", 1)[0]
    if triad not in ("gyro", "accel") or not el:
        return None
    return (0 if triad == "gyro" else 3) + "xyz".index(el[0])


@dataclass(frozen=True)
class Layout:
    """Which parameters a calibration vector holds, in canonical catalogue order.

    Parameters
    ----------
    names : tuple of str
        Parameter names (any order on input; stored in catalogue order).
    """

    names: tuple

    def __post_init__(self):
        unknown = [n for n in self.names if n not in EFFECTS]
        if unknown:
            raise KeyError(f"unknown parameter(s) {unknown}; known: {', '.join(EFFECTS)}")
        ordered = tuple(p.name for p in REGISTRY if p.name in set(self.names))
        object.__setattr__(self, "names", ordered)
        offsets = {}
        k = 0
        for n in ordered:
            offsets[n] = slice(k, k + EFFECTS[n].size)
            k += EFFECTS[n].size
        object.__setattr__(self, "_slices", offsets)
        object.__setattr__(self, "size", k)

    @classmethod
    def declared(cls, *, extra=(), exclude=()):
        """The declared model, plus further effects ``extra``, minus ``exclude``."""
        return cls(tuple(n for n in DECLARED if n not in exclude) + tuple(extra))

    def __contains__(self, name):
        return name in self._slices

    def slice(self, name):
        """Slice of parameter ``name`` in the flat vector (``KeyError`` if absent)."""
        try:
            return self._slices[name]
        except KeyError:
            raise KeyError(f"parameter {name!r} is not in this layout") from None

    def get(self, x, name, default=None):
        """Value of parameter ``name`` in vector ``x`` (a copy), or ``default`` when not in the layout."""
        if name not in self._slices:
            return default
        v = np.asarray(x)[self._slices[name]]
        return v.copy()

    def element_names(self):
        """Flat element names in vector order."""
        out = []
        for n in self.names:
            out.extend(EFFECTS[n].element_names())
        return out

    def index(self, flat):
        """Vector index of a flat element name."""
        name, element = split_element_name(flat)
        s = self.slice(name)
        return s.start if element is None else s.start + EFFECTS[name].elements.index(element)

    def with_names(self, *names):
        """A new layout with ``names`` added."""
        return Layout(self.names + tuple(names))

    def zeros(self):
        return np.zeros(self.size)

    def to_dict(self, x):
        """``{flat element name: value}`` for vector ``x``."""
        return dict(zip(self.element_names(), np.asarray(x, dtype=float).tolist()))

    def from_dict(self, values, *, missing=0.0):
        """Vector from ``{flat element name: value}``; elements not given take ``missing``."""
        x = np.full(self.size, float(missing))
        for i, nm in enumerate(self.element_names()):
            if nm in values:
                x[i] = float(values[nm])
        return x

    def embed(self, other, x_other):
        """Vector of this layout holding the values of ``x_other`` (layout ``other``); the rest zero."""
        x = self.zeros()
        for n in other.names:
            if n in self:
                x[self.slice(n)] = np.asarray(x_other)[other.slice(n)]
        return x


# ---------------------------------------------------------------------------
# IMU grades: default prior sigmas and sensor noise
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Grade:
    """Prior sigmas (SI, per parameter name) and white-noise densities of an IMU grade.

    Attributes
    ----------
    name : str
        ``"navigation"``, ``"tactical"`` or ``"consumer"``.
    prior_sigma : dict
        One-sigma prior per parameter name, SI (a scalar for every element).
    gyro_noise : float
        Angle random walk, rad/sqrt(s) (rate noise density, rad/s/sqrt(Hz)).
    accel_noise : float
        Velocity random walk, m/s/sqrt(s) (specific-force noise density).
    encoder_noise : float
        Table attitude reading noise, rad (one sigma per axis).
    """

    name: str
    prior_sigma: dict
    gyro_noise: float
    accel_noise: float
    encoder_noise: float

    def prior_vector(self, layout):
        """Prior sigmas for every element of ``layout``, shape (layout.size,)."""
        s = np.empty(layout.size)
        for n in layout.names:
            s[layout.slice(n)] = self.prior_sigma[n]
        return s


def _grade(name, *, gb, gbtc, gs, gstc, gm, ab, abtc, as_, astc, am, mount, lever, lag,
           gyro_noise, accel_noise, encoder_noise):
    prior = {
        "gyro.bias": gb, "gyro.bias_tc": gbtc, "gyro.scale": gs, "gyro.scale_tc": gstc,
        "gyro.misalignment": gm, "accel.bias": ab, "accel.bias_tc": abtc, "accel.scale": as_,
        "accel.scale_tc": astc, "accel.misalignment": am, "mount": mount, "lever_arm": lever,
        "time_lag.table": lag,
    }
    # further effects: loose priors scaled from the declared ones, by each effect's rule in the registry
    prior.update({e.name: e.prior.sigma(prior) for e in REGISTRY if e.prior is not None})
    return Grade(name, prior, gyro_noise, accel_noise, encoder_noise)


GRADES = {
    "navigation": _grade(
        "navigation",
        gb=1.0 * c.DH_TO_RS, gbtc=0.05 * c.DH_TO_RS, gs=300e-6, gstc=10e-6, gm=200 * c.ARCSEC_TO_RAD,
        ab=1e-2, abtc=5e-4, as_=1000e-6, astc=30e-6, am=200 * c.ARCSEC_TO_RAD,
        mount=0.1 * c.DEG_TO_RAD, lever=0.2, lag=0.02,
        gyro_noise=0.002 * c.DSH_TO_RSS, accel_noise=2e-5, encoder_noise=2 * c.ARCSEC_TO_RAD,
    ),
    "tactical": _grade(
        "tactical",
        gb=20.0 * c.DH_TO_RS, gbtc=1.0 * c.DH_TO_RS, gs=3000e-6, gstc=50e-6, gm=0.1 * c.DEG_TO_RAD,
        ab=5e-2, abtc=2e-3, as_=3000e-6, astc=100e-6, am=0.1 * c.DEG_TO_RAD,
        mount=0.5 * c.DEG_TO_RAD, lever=0.2, lag=0.02,
        gyro_noise=0.05 * c.DSH_TO_RSS, accel_noise=1e-4, encoder_noise=5 * c.ARCSEC_TO_RAD,
    ),
    "consumer": _grade(
        "consumer",
        gb=2.0 * c.DEG_TO_RAD, gbtc=0.05 * c.DEG_TO_RAD, gs=0.05, gstc=1e-3, gm=2.0 * c.DEG_TO_RAD,
        ab=0.5, abtc=1e-2, as_=0.05, astc=1e-3, am=2.0 * c.DEG_TO_RAD,
        mount=5.0 * c.DEG_TO_RAD, lever=0.2, lag=0.05,
        gyro_noise=0.3 * c.DSH_TO_RSS, accel_noise=2e-3, encoder_noise=60 * c.ARCSEC_TO_RAD,
    ),
}


#: The grade of a model made without a record to choose one from (a design's prediction).
DEFAULT_GRADE = "navigation"


def grade(name):
    """The :class:`Grade` called ``name`` (None: :data:`DEFAULT_GRADE`); ``KeyError`` listing the known ones."""
    try:
        return GRADES[DEFAULT_GRADE if name is None else name]
    except KeyError:
        raise KeyError(f"unknown IMU grade {name!r}; known: {', '.join(GRADES)}") from None
