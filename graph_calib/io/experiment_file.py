r"""The experiment file (HDF5): :func:`read_experiment`, :func:`write_experiment`, :func:`validate_experiment`.

The reader checks every rule of the format (``docs/data-format.md`` lists them
with their thresholds) and refuses a file that breaks one with a single
:class:`~graph_calib.errors.InputError` naming the file, the dataset, the sample
index where it applies, and what is wrong.  It never guesses and never drops
samples.  The writer runs the same checks before writing, and writes atomically
(:func:`graph_calib.io.atomic.atomic_path`).

Examples
--------
>>> import numpy as np, tempfile, pathlib
>>> from graph_calib.records.experiment import Experiment
>>> n = 100
>>> exp = Experiment(
...     t=np.arange(n) / 100.0, dtheta=np.zeros((n, 3)),
...     dv=np.tile([0.0, 0.0, 9.81 / 100.0], (n, 1)), temperature=np.full((n, 1), 25.0),
...     temperature_names=("board",), temperature_map=np.zeros(6, dtype=int),
...     rate_hz=100.0, latitude_rad=0.7, gravity_mps2=9.81, imu_id="demo")
>>> path = pathlib.Path(tempfile.mkdtemp()) / "exp.h5"
>>> write_experiment(exp, path)
>>> read_experiment(path).n_samples
100
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import h5py
import numpy as np

from graph_calib import constants as c
from graph_calib.errors import InputError
from graph_calib.records.experiment import Experiment, Table
from graph_calib.io.atomic import atomic_path
from graph_calib.io.checks import _first, _is_int, _is_real, _show, version_problem

# ---------------------------------------------------------------------------
# Format identifiers and validation thresholds (docs/data-format.md explains each)
# ---------------------------------------------------------------------------

EXPERIMENT_FORMAT = "imu-calibration-experiment"
EXPERIMENT_VERSION = 1

#: Accepted local gravity magnitude, m/s^2.  The Earth's surface spans about
#: 9.76 (high Andes at the equator) to 9.83 (poles); the margin only has to
#: catch unit mistakes (g units give about 1, ft/s^2 about 32).
GRAVITY_RANGE_MPS2 = (9.7, 9.9)
#: Largest gap between two samples of one segment, in nominal sample periods
#: (any gap is allowed at a boundary of ``/imu/segment``).
MAX_GAP_PERIODS = 3.0
#: Largest relative difference between ``rate_hz`` and ``1 / median(diff(t))``.
RATE_TOLERANCE = 0.10
#: Largest plausible angular rate, rad/s (2000 deg/s: the widest full-scale range
#: of common MEMS gyros; turntables stay well below it).
MAX_ANGULAR_RATE_RADPS = 35.0
#: Largest plausible specific force, m/s^2 (16 g: the widest full-scale range of
#: common MEMS accelerometers).
MAX_SPECIFIC_FORCE_MPS2 = 16.0 * c.G0
#: Accepted range of the record's median specific force, in units of the file's gravity.
MEDIAN_SPECIFIC_FORCE_RANGE_G = (0.5, 2.0)
#: Accepted temperature range, degC (wider than any thermal chamber; catches Kelvin).
TEMPERATURE_RANGE_DEGC = (-100.0, 200.0)
#: Largest accepted ``| |q| - 1 |`` of a quaternion.
QUATERNION_NORM_TOL = 1e-6

# Dataset and attribute names as they appear in messages.
_ROOT = '/.attrs["{}"]'
_T, _DTHETA, _DV, _TEMP = "/imu/t", "/imu/dtheta", "/imu/dv", "/imu/temperature"
_SEG = "/imu/segment"
_INT32 = np.iinfo(np.int32)
_RATE = '/imu.attrs["rate_hz"]'
_TMAP = '/imu.attrs["temperature_map"]'
_NAMES = '/imu/temperature.attrs["names"]'
_TAB_T, _TAB_Q, _TAB_VALID = "/table/t", "/table/q_nf", "/table/valid"
_QFB = '/table.attrs["q_fb_nominal"]'


def _shape_text(shape):
    return "(" + ", ".join(str(s) for s in shape) + (",)" if len(shape) == 1 else ")")


def _check_array(a, *, path, dataset, shape, kind="f"):
    """Check type, shape and finiteness of an array; ``shape`` holds ints or names of free sizes.

    Returns the array (as given).
    """
    if not isinstance(a, np.ndarray):
        raise InputError(f"expected an array, got {type(a).__name__}", path=path, dataset=dataset)
    expected = _shape_text(shape)
    fixed = [s if isinstance(s, int) else None for s in shape]
    if a.ndim != len(shape) or any(f is not None and f != n for f, n in zip(fixed, a.shape)):
        raise InputError(f"shape {_shape_text(a.shape)}, expected {expected}", path=path, dataset=dataset)
    if kind == "f":
        if a.dtype.kind != "f":
            raise InputError(
                f"dtype {a.dtype} is not floating point; expected float64 (float32 is accepted and upcast)",
                path=path, dataset=dataset)
        bad = ~np.isfinite(a)
        if bad.any():
            k = _first(bad)
            what = "NaN" if np.isnan(a[k]).any() else "infinite value"
            raise InputError(f"{what}; every value must be finite", path=path, dataset=dataset, index=k)
    elif kind == "b":
        if a.dtype.kind != "b":
            raise InputError(f"dtype {a.dtype} is not bool (numpy bool, stored by h5py as an HDF5 enum)", path=path,
                             dataset=dataset)
    elif kind == "i":
        if a.dtype.kind not in "iu":
            raise InputError(f"dtype {a.dtype} is not an integer type", path=path, dataset=dataset)
    return a


def _check_strictly_increasing(t, *, path, dataset):
    d = np.diff(t)
    bad = ~(d > 0)
    if bad.any():
        k = _first(bad) + 1
        raise InputError(
            f"time not strictly increasing: t[{k}] = {_show(t[k])} s is not after t[{k - 1}] = {_show(t[k - 1])} s",
            path=path, dataset=dataset, index=k)
    return d


def _check_unit_quaternions(q, *, path, dataset):
    err = np.abs(np.linalg.norm(q, axis=-1) - 1.0)
    bad = err > QUATERNION_NORM_TOL
    if np.any(bad):
        if q.ndim == 1:
            raise InputError(f"quaternion norm {_show(np.linalg.norm(q))} is not 1 (tolerance {QUATERNION_NORM_TOL:g})",
                             path=path, dataset=dataset)
        k = _first(bad)
        raise InputError(
            f"quaternion norm {_show(np.linalg.norm(q[k]))} is not 1 (tolerance {QUATERNION_NORM_TOL:g})",
            path=path, dataset=dataset, index=k)


# ---------------------------------------------------------------------------
# Experiment file
# ---------------------------------------------------------------------------


def _check_root(experiment, path):
    lat = experiment.latitude_rad
    ds = _ROOT.format("latitude_rad")
    if not _is_real(lat) or not math.isfinite(lat):
        raise InputError(f"latitude must be a finite number in radians, got {_show(lat)}", path=path, dataset=ds)
    if abs(lat) > math.pi / 2:
        hint = (f"; it looks like degrees ({_show(lat)} deg = {math.radians(lat):.6f} rad)"
                if abs(lat) <= 90.0 else "")
        raise InputError(f"latitude {_show(lat)} rad is beyond [-pi/2, pi/2]{hint}", path=path, dataset=ds)
    g = experiment.gravity_mps2
    ds = _ROOT.format("gravity_mps2")
    if not _is_real(g) or not math.isfinite(g):
        raise InputError(f"gravity must be a finite number in m/s^2, got {_show(g)}", path=path, dataset=ds)
    lo, hi = GRAVITY_RANGE_MPS2
    if not lo <= g <= hi:
        if 0.9 <= g <= 1.1:
            hint = "; it looks like g units, give m/s^2"
        elif 30.0 <= g <= 34.0:
            hint = "; it looks like ft/s^2, give m/s^2"
        else:
            hint = ""
        raise InputError(
            f"gravity {_show(g)} m/s^2 is outside [{lo}, {hi}], implausible on the Earth's surface{hint}",
            path=path, dataset=ds)
    for name in ("imu_id", "description"):
        v = getattr(experiment, name)
        if not isinstance(v, str):
            raise InputError(f"must be a string, got {type(v).__name__}", path=path, dataset=_ROOT.format(name))


def _check_time(experiment, path):
    t = _check_array(experiment.t, path=path, dataset=_T, shape=("N",))
    if t.shape[0] < 2:
        raise InputError(f"{t.shape[0]} sample(s); an experiment needs at least 2", path=path, dataset=_T)
    rate = experiment.rate_hz
    if not _is_real(rate) or not math.isfinite(rate) or rate <= 0:
        raise InputError(f"sample rate must be a positive finite number in Hz, got {_show(rate)}",
                         path=path, dataset=_RATE)
    d = _check_strictly_increasing(t, path=path, dataset=_T)
    median = float(np.median(d))
    if abs(median * rate - 1.0) > RATE_TOLERANCE:
        raise InputError(
            f"rate_hz = {_show(rate)} disagrees with the median sample spacing {median:.6g} s "
            f"({1.0 / median:.6g} Hz) by more than {RATE_TOLERANCE:.0%}",
            path=path, dataset=_RATE)
    return t, rate, d


def _check_segment(segment, n, path):
    """``/imu/segment``: (N,) integers that fit int32, non-decreasing; None (absent) is one segment."""
    if segment is None:
        return None
    seg = _check_array(segment, path=path, dataset=_SEG, shape=(n,), kind="i")
    bad = (seg < _INT32.min) | (seg > _INT32.max)
    if bad.any():
        k = _first(bad)
        raise InputError(f"segment {int(seg[k])} does not fit the file's int32", path=path, dataset=_SEG, index=k)
    bad = np.diff(seg) < 0
    if bad.any():
        k = _first(bad) + 1
        raise InputError(
            f"segment {int(seg[k])} after segment {int(seg[k - 1])}: segments must be non-decreasing "
            "(the samples of one piece together, the pieces in time order)",
            path=path, dataset=_SEG, index=k)
    return seg


def _check_gaps(d, rate, segment, path):
    """The discontinuity rule: no gap of more than MAX_GAP_PERIODS inside a segment."""
    gap = d > MAX_GAP_PERIODS / rate
    if segment is not None:
        gap &= np.diff(segment) == 0
    if gap.any():
        k = _first(gap) + 1
        where = "" if segment is None else f" inside segment {int(segment[k])}"
        raise InputError(
            f"gap of {d[k - 1]:.6g} s ({d[k - 1] * rate:.4g} nominal periods) before this sample{where}; "
            f"at most {MAX_GAP_PERIODS:g} periods are accepted inside a segment: mark where the pieces start in "
            f"{_SEG} (samples are never dropped)",
            path=path, dataset=_T, index=k)


def _check_temperature(experiment, n, path):
    temp = _check_array(experiment.temperature, path=path, dataset=_TEMP, shape=(n, "K"))
    k = temp.shape[1]
    if k < 1:
        raise InputError("no temperature channel; at least one is needed", path=path, dataset=_TEMP)
    lo, hi = TEMPERATURE_RANGE_DEGC
    bad = (temp < lo) | (temp > hi)
    if bad.any():
        i = _first(bad)
        val = temp[i][bad[i]][0]
        hint = "; it looks like Kelvin, give degC" if 173.0 <= val <= 473.0 else ""
        raise InputError(f"temperature {_show(val)} degC is outside [{lo:g}, {hi:g}] degC{hint}",
                         path=path, dataset=_TEMP, index=i)
    names = experiment.temperature_names
    if not isinstance(names, (tuple, list)) or not all(isinstance(s, str) for s in names):
        raise InputError(f"must be {k} strings, got {_show(names)}", path=path, dataset=_NAMES)
    if len(names) != k:
        raise InputError(f"{len(names)} name(s) for K = {k} temperature channel(s)", path=path, dataset=_NAMES)
    tmap = experiment.temperature_map
    tmap = _check_array(np.asarray(tmap) if isinstance(tmap, (list, tuple)) else tmap,
                        path=path, dataset=_TMAP, shape=(6,), kind="i")
    bad = (tmap < 0) | (tmap >= k)
    if bad.any():
        raise InputError(
            f"channel {int(tmap[_first(bad)])} for sensor {_first(bad)} (gyro x, y, z, accel x, y, z) "
            f"is not in [0, {k}): six integer channel indices are needed",
            path=path, dataset=_TMAP)


def _effective_dt(t, rate):
    """Sample intervals, s, shape (N,), each no shorter than the nominal period (see the docs)."""
    dt = np.empty_like(t, dtype=np.float64)
    dt[0] = 1.0 / rate
    dt[1:] = np.diff(t)
    return np.maximum(dt, 1.0 / rate)


def _check_plausible_increments(dtheta, dv, t, rate, gravity, path):
    dt = _effective_dt(t, rate)
    omega = np.linalg.norm(dtheta, axis=1) / dt
    bad = omega > MAX_ANGULAR_RATE_RADPS
    if bad.any():
        k = _first(bad)
        raise InputError(
            f"|dtheta| / dt = {omega[k]:.6g} rad/s exceeds {MAX_ANGULAR_RATE_RADPS:g} rad/s "
            f"({MAX_ANGULAR_RATE_RADPS * c.RAD_TO_DEG:.0f} deg/s): degrees written for radians, "
            "or rates written for increments? (graph-calib import csv: --gyro-units deg/s for a log in deg/s)",
            path=path, dataset=_DTHETA, index=k)
    f = np.linalg.norm(dv, axis=1) / dt
    bad = f > MAX_SPECIFIC_FORCE_MPS2
    if bad.any():
        k = _first(bad)
        raise InputError(
            f"|dv| / dt = {f[k]:.6g} m/s^2 exceeds {MAX_SPECIFIC_FORCE_MPS2 / c.G0:g} g: "
            "specific force written for velocity increments, or wrong units?",
            path=path, dataset=_DV, index=k)
    lo, hi = MEDIAN_SPECIFIC_FORCE_RANGE_G
    med = float(np.median(f))
    if not lo * gravity <= med <= hi * gravity:
        raise InputError(
            f"median |dv| / dt over the record is {med:.6g} m/s^2, outside [{lo:g}, {hi:g}] x gravity "
            f"({gravity:g} m/s^2): increments in g units, or not in m/s? (graph-calib import csv: --accel-units g for "
            "a log in g)",
            path=path, dataset=_DV)


def _check_table(table, path):
    if not isinstance(table, Table):
        raise InputError(f"expected a Table, got {type(table).__name__}", path=path, dataset="/table")
    t = _check_array(table.t, path=path, dataset=_TAB_T, shape=("M",))
    m = t.shape[0]
    q = _check_array(table.q_nf, path=path, dataset=_TAB_Q, shape=(m, 4))
    _check_array(table.valid, path=path, dataset=_TAB_VALID, shape=(m,), kind="b")
    if m > 1:
        _check_strictly_increasing(t, path=path, dataset=_TAB_T)
    _check_unit_quaternions(q, path=path, dataset=_TAB_Q)
    qfb = table.q_fb_nominal
    qfb = _check_array(np.asarray(qfb) if isinstance(qfb, (list, tuple)) else qfb,
                       path=path, dataset=_QFB, shape=(4,))
    _check_unit_quaternions(qfb, path=path, dataset=_QFB)


def validate_experiment(experiment, *, path):
    """Check an experiment against every rule of the experiment file format.

    Used by :func:`read_experiment` on what it read and by
    :func:`write_experiment` before it writes.  The rules and their thresholds are
    listed in ``docs/data-format.md``; they are checked in the order root
    attributes, time and rate, segments, gaps inside a segment, increments'
    shapes and values, temperatures, plausibility of the increments, table.

    Parameters
    ----------
    experiment : Experiment
        Arrays may be float32 (they are upcast on reading and writing).
    path : str or Path
        File the experiment comes from or goes to, named in the message.

    Raises
    ------
    InputError
        On the first rule broken: names the file, the dataset, the sample index
        where it applies, and what is wrong.
    """
    if not isinstance(experiment, Experiment):
        raise InputError(f"expected an Experiment, got {type(experiment).__name__}", path=path)
    _check_root(experiment, path)
    t, rate, d = _check_time(experiment, path)
    n = t.shape[0]
    segment = _check_segment(experiment.segment, n, path)
    _check_gaps(d, rate, segment, path)
    # shapes and finiteness of the increments before the temperatures, plausibility after
    dtheta = _check_array(experiment.dtheta, path=path, dataset=_DTHETA, shape=(n, 3))
    dv = _check_array(experiment.dv, path=path, dataset=_DV, shape=(n, 3))
    _check_temperature(experiment, n, path)
    _check_plausible_increments(dtheta, dv, t, rate, float(experiment.gravity_mps2), path)
    if experiment.table is not None:
        _check_table(experiment.table, path)


def _as_str(value):
    if isinstance(value, bytes):
        return value.decode("utf-8")
    return value


def _attr_str_tuple(value):
    """A names attribute as read by h5py -> tuple of str (a scalar string is one name)."""
    if isinstance(value, (str, bytes)):
        return (_as_str(value),)
    arr = np.asarray(value)
    if arr.ndim == 1 and arr.dtype.kind in "OSU":
        out = tuple(_as_str(v) for v in arr.tolist())
        if all(isinstance(s, str) for s in out):
            return out
    return value  # left for validate_experiment to refuse


def _attr_scalar(value):
    """A scalar attribute as a Python number or str; anything else left as is (refused later).

    A one-element array counts as a scalar: MATLAB and some HDF5 writers store scalars so.
    """
    if isinstance(value, (bytes, np.bytes_)):
        return value.decode("utf-8")
    if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind in "fiuSO":
        value = value.reshape(())[()]  # () or a 1-element array (as MATLAB writes scalars)
        if isinstance(value, bytes):
            value = value.decode("utf-8")
    if isinstance(value, np.generic):
        return value.item()
    return value


def _dataset(group, name, path):
    full = f"{group.name.rstrip('/')}/{name}"
    if name not in group:
        raise InputError("missing dataset", path=path, dataset=full)
    obj = group[name]
    if not isinstance(obj, h5py.Dataset):
        raise InputError("is a group, expected a dataset", path=path, dataset=full)
    return obj[()]


def _group(f, name, path):
    if name not in f:
        raise InputError("missing group", path=path, dataset=f"/{name}")
    obj = f[name]
    if not isinstance(obj, h5py.Group):
        raise InputError("is a dataset, expected a group", path=path, dataset=f"/{name}")
    return obj


def _require_attr(obj, name, path, dataset):
    if name not in obj.attrs:
        raise InputError("missing attribute", path=path, dataset=dataset)
    return obj.attrs[name]


def _float64(a):
    return np.asarray(a, dtype=np.float64)


@contextlib.contextmanager
def _damage_as_input_error(path):
    """h5py's errors on a damaged file (and strings that are not UTF-8) as one InputError naming the file."""
    try:
        yield
    except InputError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
        first = (str(exc).strip().splitlines() or [""])[0]
        raise InputError(f"cannot be read, damaged or not written as HDF5 of this format "
                         f"({type(exc).__name__}: {first})", path=path) from None


def read_experiment(path):
    """Read and validate an experiment file (HDF5).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Experiment
        Floating arrays as float64 (float32 in the file is upcast),
        ``temperature_map`` as int64, ``segment`` as int32 (None when the
        file has no ``/imu/segment``), ``source`` set to ``str(path)``.  The
        optional ``/truth`` group and any further datasets are not read.

    Raises
    ------
    InputError
        If the file is missing, is not HDF5, or breaks any rule (see
        :func:`validate_experiment` and ``docs/data-format.md``).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path=path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({exc})", path=path) from None
    with _damage_as_input_error(path), f:
        fmt = _attr_scalar(_require_attr(f, "format", path, _ROOT.format("format")))
        if fmt != EXPERIMENT_FORMAT:
            raise InputError(f"format is {_show(fmt)}, expected {_show(EXPERIMENT_FORMAT)}",
                             path=path, dataset=_ROOT.format("format"))
        version = _attr_scalar(_require_attr(f, "version", path, _ROOT.format("version")))
        problem = version_problem(version, EXPERIMENT_VERSION)
        if problem:
            raise InputError(problem, path=path, dataset=_ROOT.format("version"))
        root = {name: _attr_scalar(_require_attr(f, name, path, _ROOT.format(name)))
                for name in ("latitude_rad", "gravity_mps2", "imu_id")}
        description = _attr_scalar(f.attrs.get("description", ""))
        imu = _group(f, "imu", path)
        rate = _attr_scalar(_require_attr(imu, "rate_hz", path, _RATE))
        tmap = imu.attrs.get("temperature_map", np.zeros(6, dtype=np.int64))
        t = _dataset(imu, "t", path)
        dtheta = _dataset(imu, "dtheta", path)
        dv = _dataset(imu, "dv", path)
        temperature = _dataset(imu, "temperature", path)
        names = _attr_str_tuple(_require_attr(imu["temperature"], "names", path, _NAMES))
        segment = _dataset(imu, "segment", path) if "segment" in imu else None
        table = None
        if "table" in f:
            tab = _group(f, "table", path)
            table = Table(
                t=_dataset(tab, "t", path), q_nf=_dataset(tab, "q_nf", path),
                valid=_dataset(tab, "valid", path),
                q_fb_nominal=np.asarray(tab.attrs.get("q_fb_nominal", np.array([1.0, 0.0, 0.0, 0.0]))),
            )
    raw = Experiment(
        t=t, dtheta=dtheta, dv=dv, temperature=temperature, temperature_names=names,
        temperature_map=np.asarray(tmap), rate_hz=rate, latitude_rad=root["latitude_rad"],
        gravity_mps2=root["gravity_mps2"], imu_id=root["imu_id"], description=description,
        table=table, source=str(path), segment=segment,
    )
    validate_experiment(raw, path=path)
    if table is not None:
        table = Table(t=_float64(table.t), q_nf=_float64(table.q_nf), valid=np.asarray(table.valid, dtype=bool),
                      q_fb_nominal=_float64(table.q_fb_nominal))
    return Experiment(
        t=_float64(t), dtheta=_float64(dtheta), dv=_float64(dv), temperature=_float64(temperature),
        temperature_names=tuple(names), temperature_map=np.asarray(tmap, dtype=np.int64),
        rate_hz=float(rate), latitude_rad=float(root["latitude_rad"]),
        gravity_mps2=float(root["gravity_mps2"]), imu_id=root["imu_id"], description=description,
        table=table, source=str(path), segment=None if segment is None else np.asarray(segment, dtype=np.int32),
    )


def write_experiment(experiment, path, *, compression=None):
    """Validate an experiment and write it atomically as an experiment file (HDF5).

    Parameters
    ----------
    experiment : Experiment
    path : str or Path
        Target file; replaced atomically if it exists.
    compression : str or None
        h5py compression filter for the datasets (``"gzip"``, ``"lzf"``), none by default.

    Raises
    ------
    InputError
        If the experiment breaks a rule (nothing is written) or the folder does not exist.
    """
    path = Path(path)
    validate_experiment(experiment, path=path)
    e = experiment
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = EXPERIMENT_FORMAT
            f.attrs["version"] = np.int64(EXPERIMENT_VERSION)
            f.attrs["latitude_rad"] = np.float64(e.latitude_rad)
            f.attrs["gravity_mps2"] = np.float64(e.gravity_mps2)
            f.attrs["imu_id"] = e.imu_id
            f.attrs["description"] = e.description
            imu = f.create_group("imu")
            imu.attrs["rate_hz"] = np.float64(e.rate_hz)
            imu.attrs["temperature_map"] = np.asarray(e.temperature_map, dtype=np.int64)
            for name in ("t", "dtheta", "dv", "temperature"):
                imu.create_dataset(name, data=_float64(getattr(e, name)), compression=compression)
            imu["temperature"].attrs["names"] = np.array(list(e.temperature_names), dtype=h5py.string_dtype())
            if e.segment is not None:
                imu.create_dataset("segment", data=np.asarray(e.segment, dtype=np.int32), compression=compression)
            if e.table is not None:
                tab = f.create_group("table")
                tab.attrs["q_fb_nominal"] = _float64(e.table.q_fb_nominal)
                tab.create_dataset("t", data=_float64(e.table.t), compression=compression)
                tab.create_dataset("q_nf", data=_float64(e.table.q_nf), compression=compression)
                tab.create_dataset("valid", data=np.asarray(e.table.valid, dtype=bool), compression=compression)
