r"""Reading, writing and validating the three files of ``data-format.md``.

* the experiment file (HDF5): :func:`read_experiment`, :func:`write_experiment`,
  :func:`validate_experiment`;
* the result file (JSON): :func:`read_result`, :func:`write_result`,
  :func:`validate_result`;
* the campaign manifest (TOML): :func:`read_manifest` giving a :class:`Campaign`.

Readers check every rule of the format (``docs/data-format.md`` lists them with
their thresholds) and refuse a file that breaks one with a single
:class:`~graph_calib.errors.InputError` naming the file, the dataset or key, the
sample index where it applies, and what is wrong.  They never guess and never
drop samples.  The writers run the same checks before writing, and write
atomically (a temporary file in the target folder, then :func:`os.replace`), so
that an error or an interruption never leaves a half-written file.

The atomic helpers :func:`atomic_path`, :func:`atomic_write_text` and
:func:`atomic_write_json` are for every module that writes files.

Examples
--------
>>> import numpy as np, tempfile, pathlib
>>> from graph_calib.experiment import Experiment
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
import json
import math
import numbers
import os
import tempfile
import tomllib
from dataclasses import dataclass, field
from pathlib import Path, PurePath

import h5py
import numpy as np

from graph_calib import constants as c
from graph_calib import params
from graph_calib.errors import InputError
from graph_calib.experiment import Experiment, Result, Table

# ---------------------------------------------------------------------------
# Format identifiers and validation thresholds (docs/data-format.md explains each)
# ---------------------------------------------------------------------------

EXPERIMENT_FORMAT = "imu-calibration-experiment"
EXPERIMENT_VERSION = 1
RESULT_FORMAT = "imu-calibration-result"
RESULT_VERSION = 1

#: Accepted local gravity magnitude, m/s^2.  The Earth's surface spans about
#: 9.76 (high Andes at the equator) to 9.83 (poles); the margin only has to
#: catch unit mistakes (g units give about 1, ft/s^2 about 32).
GRAVITY_RANGE_MPS2 = (9.7, 9.9)
#: Largest gap between two samples, in nominal sample periods.
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
#: Relative asymmetry accepted in a result covariance, ``|P - P.T| <= tol * sqrt(d_i d_j)``.
COVARIANCE_SYMMETRY_TOL = 1e-6

# Dataset and attribute names as they appear in messages.
_ROOT = '/.attrs["{}"]'
_T, _DTHETA, _DV, _TEMP = "/imu/t", "/imu/dtheta", "/imu/dv", "/imu/temperature"
_RATE = '/imu.attrs["rate_hz"]'
_TMAP = '/imu.attrs["temperature_map"]'
_NAMES = '/imu/temperature.attrs["names"]'
_TAB_T, _TAB_Q, _TAB_VALID = "/table/t", "/table/q_nf", "/table/valid"
_QFB = '/table.attrs["q_fb_nominal"]'



def _show(x):
    """``repr`` of a value for messages, numpy scalars shown as plain Python numbers."""
    if isinstance(x, np.generic):
        x = x.item()
    return repr(x)

# ---------------------------------------------------------------------------
# Atomic writing
# ---------------------------------------------------------------------------


def _umask():
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    The temporary file lives in the same folder, so the final :func:`os.replace`
    is atomic: readers see either the old file or the complete new one.  If the
    body raises (or is interrupted), the temporary file is removed and ``path``
    is left as it was.

    Parameters
    ----------
    path : str or Path
        Final file path.  Its folder must exist.

    Yields
    ------
    Path
        An empty file in the same folder, to be written (and closed) by the body.

    Raises
    ------
    InputError
        If the folder does not exist or ``path`` is a folder.
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise InputError(f"folder {folder} does not exist", path=path)
    if path.is_dir():
        raise InputError("is a folder, expected a file name", path=path)
    fd, tmp_name = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        mode = (path.stat().st_mode & 0o777) if path.exists() else (0o666 & ~_umask())
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
    with contextlib.suppress(OSError):  # make the rename durable where the OS allows it
        dir_fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def atomic_write_text(path, text, *, encoding="utf-8"):
    """Write ``text`` to ``path`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or Path
    text : str
    encoding : str
    """
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding=encoding)


def to_json_builtin(obj):
    """A copy of ``obj`` made of JSON built-in types.

    numpy arrays become (nested) lists, numpy scalars Python numbers, tuples
    lists, paths strings.  Dictionary keys must be strings.

    Raises
    ------
    TypeError
        For anything else.
    """
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"JSON object keys must be strings, got {_show(k)}")
            out[k] = to_json_builtin(v)
        return out
    if isinstance(obj, (list, tuple)):
        return [to_json_builtin(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_json_builtin(obj.tolist())
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        return float(obj)
    if isinstance(obj, PurePath):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} to JSON: {_show(obj)}")


def _is_scalar_json(v):
    return v is None or isinstance(v, (bool, int, float, str))


def _dump(obj, level, indent, allow_nan):
    """JSON text: objects indented, lists of scalars and small flat objects on one line."""
    if isinstance(obj, dict):
        if not obj:
            return "{}"
        if len(obj) <= 4 and all(_is_scalar_json(v) for v in obj.values()):
            return json.dumps(obj, allow_nan=allow_nan)
        pad = " " * (indent * (level + 1))
        items = [f"{pad}{json.dumps(k)}: {_dump(v, level + 1, indent, allow_nan)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + " " * (indent * level) + "}"
    if isinstance(obj, list):
        if all(_is_scalar_json(v) for v in obj):
            return json.dumps(obj, allow_nan=allow_nan)
        pad = " " * (indent * (level + 1))
        items = [pad + _dump(v, level + 1, indent, allow_nan) for v in obj]
        return "[\n" + ",\n".join(items) + "\n" + " " * (indent * level) + "]"
    return json.dumps(obj, allow_nan=allow_nan)


def dumps_json(obj, *, indent=2, allow_nan=False):
    """JSON text of ``obj`` (numpy-safe), floats written with ``repr`` so they read back exactly.

    Nested objects are indented; lists of numbers (matrix rows included) and small
    flat objects such as ``{"value": v, "sigma": s}`` stay on one line.

    Parameters
    ----------
    obj : object
        Anything :func:`to_json_builtin` accepts.
    indent : int
    allow_nan : bool
        Whether NaN and infinities may be written (they are not standard JSON; by
        default they raise ``ValueError``).
    """
    return _dump(to_json_builtin(obj), 0, indent, allow_nan) + "\n"


def atomic_write_json(path, obj, *, indent=2, allow_nan=False):
    """Write ``obj`` as JSON to ``path`` atomically; numpy arrays and scalars are accepted.

    Parameters
    ----------
    path : str or Path
    obj : object
        See :func:`dumps_json`.
    indent : int
    allow_nan : bool
        See :func:`dumps_json`.
    """
    text = dumps_json(obj, indent=indent, allow_nan=allow_nan)  # fails before any file exists
    atomic_write_text(path, text)


# ---------------------------------------------------------------------------
# Small checks shared by the three files
# ---------------------------------------------------------------------------


def _is_real(x):
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def _is_int(x):
    return isinstance(x, numbers.Integral) and not isinstance(x, (bool, np.bool_))


def _first(mask):
    """Index of the first True of a boolean array along its first axis."""
    mask = np.asarray(mask)
    if mask.ndim > 1:
        mask = mask.reshape(mask.shape[0], -1).any(axis=1)
    return int(np.flatnonzero(mask)[0])


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
    gap = d > MAX_GAP_PERIODS / rate
    if gap.any():
        k = _first(gap) + 1
        raise InputError(
            f"gap of {d[k - 1]:.6g} s ({d[k - 1] * rate:.3g} nominal periods) before this sample; "
            f"at most {MAX_GAP_PERIODS:g} periods are accepted (split the record, samples are never dropped)",
            path=path, dataset=_T, index=k)
    return t, rate


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
            "or rates written for increments?",
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
            f"({gravity:g} m/s^2): increments in g units, or not in m/s?",
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
    attributes, time and rate, increments' shapes and values, temperatures,
    plausibility of the increments, table.

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
    t, rate = _check_time(experiment, path)
    n = t.shape[0]
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


def read_experiment(path):
    """Read and validate an experiment file (HDF5).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Experiment
        Floating arrays as float64 (float32 in the file is upcast),
        ``temperature_map`` as int64, ``source`` set to ``str(path)``.  The
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
    with f:
        fmt = _attr_scalar(_require_attr(f, "format", path, _ROOT.format("format")))
        if fmt != EXPERIMENT_FORMAT:
            raise InputError(f"format is {_show(fmt)}, expected {_show(EXPERIMENT_FORMAT)}",
                             path=path, dataset=_ROOT.format("format"))
        version = _attr_scalar(_require_attr(f, "version", path, _ROOT.format("version")))
        if not _is_int(version) or version != EXPERIMENT_VERSION:
            raise InputError(f"version {_show(version)} is not supported (this reader knows version {EXPERIMENT_VERSION})",
                             path=path, dataset=_ROOT.format("version"))
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
        table=table, source=str(path),
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
        table=table, source=str(path),
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
            if e.table is not None:
                tab = f.create_group("table")
                tab.attrs["q_fb_nominal"] = _float64(e.table.q_fb_nominal)
                tab.create_dataset("t", data=_float64(e.table.t), compression=compression)
                tab.create_dataset("q_nf", data=_float64(e.table.q_nf), compression=compression)
                tab.create_dataset("valid", data=np.asarray(e.table.valid, dtype=bool), compression=compression)


# ---------------------------------------------------------------------------
# Result file
# ---------------------------------------------------------------------------

_RESULT_KEYS = ("format", "version", "source", "solver", "t_ref_degC", "temperature_range_degC",
                "effects", "estimates", "covariance", "residuals")
_REQUIRED_RESULT_KEYS = tuple(k for k in _RESULT_KEYS if k != "covariance")


def _check_element_name(name, *, path, dataset):
    if not isinstance(name, str):
        raise InputError(f"parameter element name must be a string, got {_show(name)}", path=path, dataset=dataset)
    try:
        params.split_element_name(name)
    except KeyError:
        raise InputError(f"unknown parameter element {_show(name)} (see the catalogue of model.md)",
                         path=path, dataset=dataset) from None


def _check_finite_real(v, *, path, dataset, what="value"):
    if not _is_real(v) or not math.isfinite(v):
        raise InputError(f"{what} must be a finite number, got {_show(v)}", path=path, dataset=dataset)


def validate_result(result, *, path):
    """Check a :class:`~graph_calib.experiment.Result` against the result file format.

    Rules: ``source`` and ``solver`` strings; ``t_ref_degC`` finite;
    ``temperature_range_degC`` two finite numbers, low first; ``effects`` known
    parameter names; estimate names known flat element names with finite values;
    a one-sigma (finite, non-negative) for every estimate unless the solver is
    ``"truth"``, and none for truth; the covariance, when present, square,
    finite, symmetric, with a non-negative diagonal and one known, unique name per
    row; ``residuals`` and ``extra`` objects, ``extra`` not reusing a layout key.

    Parameters
    ----------
    result : Result
    path : str or Path
        File named in the message.

    Raises
    ------
    InputError
        On the first rule broken, naming the file and the key.
    """
    r = result
    if not isinstance(r, Result):
        raise InputError(f"expected a Result, got {type(r).__name__}", path=path)
    for key in ("source", "solver"):
        if not isinstance(getattr(r, key), str) or (key == "solver" and not r.solver):
            raise InputError(f"must be a non-empty string, got {_show(getattr(r, key))}" if key == "solver"
                             else f"must be a string, got {_show(getattr(r, key))}", path=path, dataset=key)
    _check_finite_real(r.t_ref_degC, path=path, dataset="t_ref_degC")
    rng = r.temperature_range_degC
    if not isinstance(rng, (list, tuple)) or len(rng) != 2:
        raise InputError(f"must be [low, high], got {_show(rng)}", path=path, dataset="temperature_range_degC")
    for v in rng:
        _check_finite_real(v, path=path, dataset="temperature_range_degC")
    if rng[0] > rng[1]:
        raise InputError(f"low {_show(rng[0])} above high {_show(rng[1])}", path=path, dataset="temperature_range_degC")
    if not isinstance(r.effects, (list, tuple)):
        raise InputError(f"must be a list of parameter names, got {_show(r.effects)}", path=path, dataset="effects")
    for name in r.effects:
        if not isinstance(name, str) or name not in params.SPECS:
            raise InputError(f"unknown parameter {_show(name)}; known: {', '.join(params.SPECS)}",
                             path=path, dataset="effects")
    if not isinstance(r.values, dict):
        raise InputError("must be an object of estimates", path=path, dataset="estimates")
    for name, v in r.values.items():
        ds = f'estimates["{name}"]'
        _check_element_name(name, path=path, dataset=ds)
        _check_finite_real(v, path=path, dataset=ds + ".value")
    truth = r.solver == "truth"
    if truth:
        if r.sigmas:
            raise InputError("a truth file has no sigma", path=path, dataset="estimates")
    else:
        if not isinstance(r.sigmas, dict):
            raise InputError(f"solver {_show(r.solver)} gives no sigma; every estimate needs one unless the solver is "
                             "'truth'", path=path, dataset="estimates")
        for name in r.values:
            ds = f'estimates["{name}"].sigma'
            if name not in r.sigmas:
                raise InputError("missing sigma", path=path, dataset=ds)
            s = r.sigmas[name]
            _check_finite_real(s, path=path, dataset=ds, what="sigma")
            if s < 0:
                raise InputError(f"negative sigma {_show(s)}", path=path, dataset=ds)
        extra = [k for k in r.sigmas if k not in r.values]
        if extra:
            raise InputError(f"sigma without a value for {_show(extra[0])}", path=path, dataset="estimates")
    if (r.covariance is None) != (r.covariance_names is None):
        raise InputError("names and matrix go together", path=path, dataset="covariance")
    if r.covariance is not None:
        names = r.covariance_names
        if not isinstance(names, (list, tuple)):
            raise InputError(f"names must be a list, got {_show(names)}", path=path, dataset="covariance.names")
        for name in names:
            _check_element_name(name, path=path, dataset="covariance.names")
        if len(set(names)) != len(names):
            dup = next(n for n in names if list(names).count(n) > 1)
            raise InputError(f"name {_show(dup)} appears twice", path=path, dataset="covariance.names")
        p = len(names)
        cov = r.covariance
        if not isinstance(cov, np.ndarray) or cov.dtype.kind not in "fiu" or cov.shape != (p, p):
            shape = getattr(cov, "shape", None)
            raise InputError(f"matrix must be a square {p} x {p} array of numbers matching the {p} names, "
                             f"got shape {shape}", path=path, dataset="covariance.matrix")
        cov = cov.astype(np.float64)
        bad = ~np.isfinite(cov)
        if bad.any():
            i = _first(bad)
            raise InputError(f"non-finite value in row {i}", path=path, dataset="covariance.matrix")
        d = np.diag(cov)
        if (d < 0).any():
            raise InputError(f"negative variance for {_show(names[_first(d < 0)])}", path=path,
                             dataset="covariance.matrix")
        scale = np.sqrt(np.outer(d, d))
        asym = np.abs(cov - cov.T) > COVARIANCE_SYMMETRY_TOL * scale
        if asym.any():
            i = _first(asym)
            j = int(np.flatnonzero(asym[i])[0])
            raise InputError(f"not symmetric: element ({i}, {j}) = {_show(cov[i, j])} but ({j}, {i}) = {_show(cov[j, i])}",
                             path=path, dataset="covariance.matrix")
    if not isinstance(r.residuals, dict):
        raise InputError("must be an object", path=path, dataset="residuals")
    if not isinstance(r.extra, dict):
        raise InputError("extra top-level keys must be an object", path=path)
    clash = [k for k in r.extra if k in _RESULT_KEYS]
    if clash:
        raise InputError(f"extra key {_show(clash[0])} clashes with a key of the result layout", path=path,
                         dataset=clash[0])


def result_to_dict(result):
    """The JSON object of a result file, keys in the order of ``data-format.md``.

    Parameters
    ----------
    result : Result

    Returns
    -------
    dict
        ``format, version, source, solver, t_ref_degC, temperature_range_degC,
        effects, estimates, covariance`` (only when present), ``residuals``, then
        the keys of ``result.extra`` in their order.
    """
    r = result
    truth = r.solver == "truth"
    estimates = {}
    for name, v in r.values.items():
        entry = {"value": float(v)}
        if not truth:
            entry["sigma"] = float(r.sigmas[name])
        estimates[name] = entry
    out = {
        "format": RESULT_FORMAT, "version": RESULT_VERSION, "source": r.source, "solver": r.solver,
        "t_ref_degC": float(r.t_ref_degC),
        "temperature_range_degC": [float(v) for v in r.temperature_range_degC],
        "effects": list(r.effects), "estimates": estimates,
    }
    if r.covariance is not None:
        out["covariance"] = {"names": list(r.covariance_names),
                             "matrix": np.asarray(r.covariance, dtype=np.float64).tolist()}
    out["residuals"] = r.residuals
    out.update(r.extra)
    return out


#: ``format`` attribute of a residual-series file.
RESIDUALS_FORMAT = "imu-calibration-residuals"


def write_residuals(path, series, *, solver, source, kind="whitened residual"):
    """Write a solver's residual time series atomically (HDF5), for residual analysis elsewhere.

    Layout: root attributes ``format = "imu-calibration-residuals"``, ``version = 1``,
    ``solver``, ``source`` (the experiment file name) and ``quantity`` (``kind``:
    ``"whitened residual"`` for the factor graph, ``"normalised innovation"`` for the
    filter); one group per factor kind (``rotation``, ``gravity``, ``encoder``) with
    ``t`` (F,) float64, s, on the experiment's clock (keyframe start for gravity,
    keyframe end for rotation, reading time for encoder) and ``values`` (F, 3)
    float64, dimensionless (residual over its one-sigma noise, per axis).

    Parameters
    ----------
    path : str or Path
    series : dict
        ``{kind: (t (F,), values (F, 3))}``.
    solver, source, kind : str
    """
    path = Path(path)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = RESIDUALS_FORMAT
            f.attrs["version"] = 1
            f.attrs["solver"] = str(solver)
            f.attrs["source"] = str(source)
            f.attrs["quantity"] = str(kind)
            for name, (t, v) in series.items():
                t = np.asarray(t, dtype=np.float64)
                v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
                if t.shape != (v.shape[0],):
                    raise ValueError(f"{name}: {t.shape[0]} times for {v.shape[0]} residual rows")
                g = f.create_group(name)
                g.create_dataset("t", data=t)
                g.create_dataset("values", data=v)


def read_residuals(path):
    """``(attributes dict, {kind: (t, values)})`` of a file written by :func:`write_residuals`."""
    path = Path(path)
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != RESIDUALS_FORMAT:
            raise InputError(f"not a residual-series file (format {f.attrs.get('format')!r})", path=path)
        attrs = {k: (v.decode() if isinstance(v, bytes) else v.item() if hasattr(v, "item") else v)
                 for k, v in f.attrs.items()}
        return attrs, {name: (g["t"][()], g["values"][()]) for name, g in f.items()}


def write_result(result, path):
    """Validate a result and write it atomically as a result file (JSON).

    Floats are written with ``repr`` and read back bit for bit.

    Parameters
    ----------
    result : Result
    path : str or Path

    Raises
    ------
    InputError
        If the result breaks a rule of the format (nothing is written).
    """
    path = Path(path)
    validate_result(result, path=path)
    try:
        text = dumps_json(result_to_dict(result))
    except (TypeError, ValueError) as exc:  # a program's mistake, not bad input
        raise ValueError(f"{path}: cannot write the result as JSON: {exc}") from exc
    atomic_write_text(path, text)


def _reject_constant(name):
    raise ValueError(f"{name} is not a finite number (not allowed in these files)")


def _load_json(path):
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path=path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", path=path) from None
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise InputError(f"JSON syntax error at line {exc.lineno}, column {exc.colno}: {exc.msg}",
                         path=path) from None
    except ValueError as exc:
        raise InputError(str(exc), path=path) from None


def read_result(path):
    """Read and validate a result (or truth) file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Result
        ``sigmas`` None for truth; ``covariance`` a float64 array or None;
        top-level keys beyond the layout in ``extra``.

    Raises
    ------
    InputError
        Naming the file and the key: bad JSON (with line), wrong format or
        version, a missing key, an unknown parameter, a missing sigma, a
        malformed covariance, a non-finite number.
    """
    path = Path(path)
    doc = _load_json(path)
    if not isinstance(doc, dict):
        raise InputError("top level must be a JSON object", path=path)
    for key in ("format", "version"):
        if key not in doc:
            raise InputError("missing key", path=path, dataset=key)
    if doc["format"] != RESULT_FORMAT:
        raise InputError(f"format is {_show(doc['format'])}, expected {_show(RESULT_FORMAT)}", path=path, dataset="format")
    if not _is_int(doc["version"]) or doc["version"] != RESULT_VERSION:
        raise InputError(f"version {_show(doc['version'])} is not supported (this reader knows version {RESULT_VERSION})",
                         path=path, dataset="version")
    for key in _REQUIRED_RESULT_KEYS:
        if key not in doc:
            raise InputError("missing key", path=path, dataset=key)
    truth = doc["solver"] == "truth"
    est = doc["estimates"]
    if not isinstance(est, dict):
        raise InputError("must be an object {name: {value, sigma}}", path=path, dataset="estimates")
    values, sigmas = {}, ({} if not truth else None)
    for name, entry in est.items():
        ds = f'estimates["{name}"]'
        if not isinstance(entry, dict) or "value" not in entry:
            raise InputError("must be an object with a 'value'", path=path, dataset=ds)
        unknown = [k for k in entry if k not in ("value", "sigma")]
        if unknown:
            raise InputError(f"unknown key {_show(unknown[0])} (an estimate holds 'value' and 'sigma')",
                             path=path, dataset=ds)
        values[name] = entry["value"]
        if truth:
            if "sigma" in entry:
                raise InputError("a truth file has no sigma", path=path, dataset=ds + ".sigma")
        elif "sigma" in entry:
            sigmas[name] = entry["sigma"]
    cov_names = cov = None
    if "covariance" in doc:
        cv = doc["covariance"]
        if not isinstance(cv, dict) or set(cv) != {"names", "matrix"}:
            raise InputError("must be an object with exactly 'names' and 'matrix'", path=path, dataset="covariance")
        cov_names = cv["names"]
        try:
            cov = np.array(cv["matrix"], dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError("matrix must be a list of equal-length rows of numbers", path=path,
                             dataset="covariance.matrix") from None
        if isinstance(cov_names, list):
            cov_names = tuple(cov_names)
    rng = doc["temperature_range_degC"]
    result = Result(
        source=doc["source"], solver=doc["solver"], t_ref_degC=doc["t_ref_degC"],
        temperature_range_degC=tuple(rng) if isinstance(rng, list) else rng,
        effects=tuple(doc["effects"]) if isinstance(doc["effects"], list) else doc["effects"],
        values=values, sigmas=sigmas, covariance_names=cov_names, covariance=cov,
        residuals=doc["residuals"], extra={k: v for k, v in doc.items() if k not in _RESULT_KEYS},
    )
    validate_result(result, path=path)
    return Result(
        source=result.source, solver=result.solver, t_ref_degC=float(result.t_ref_degC),
        temperature_range_degC=tuple(float(v) for v in result.temperature_range_degC),
        effects=result.effects, values={k: float(v) for k, v in values.items()},
        sigmas=None if truth else {k: float(v) for k, v in sigmas.items()},
        covariance_names=cov_names, covariance=cov, residuals=result.residuals, extra=result.extra,
    )


# ---------------------------------------------------------------------------
# Campaign manifest
# ---------------------------------------------------------------------------

#: Options of the ``[solver]`` table: name -> (description, check returning an error text or None).
SOLVER_OPTIONS = {
    "solvers": ("which solvers run: 'sqrt-kf', 'factor-graph' or 'both'",
                lambda v: None if v in ("sqrt-kf", "factor-graph", "both")
                else "must be 'sqrt-kf', 'factor-graph' or 'both'"),
    "keyframe_s": ("length of one keyframe (preintegration interval), s",
                   lambda v: None if _is_real(v) and math.isfinite(v) and v > 0 else "must be a positive number"),
    "max_iterations": ("largest number of solver iterations",
                       lambda v: None if _is_int(v) and v > 0 else "must be a positive integer"),
}

_MANIFEST_KEYS = ("imu", "experiment", "priors", "model", "solver")
_IMU_KEYS = ("id", "grade")
_EXPERIMENT_KEYS = ("file", "t_ref_degC", "name")
_MODEL_KEYS = ("effects", "exclude")


@dataclass(frozen=True)
class CampaignExperiment:
    """One ``[[experiment]]`` of a manifest.

    Attributes
    ----------
    file : Path
        Experiment file, resolved against the manifest's folder (absolute).
    t_ref_degC : float or None
        Reference temperature, degC; None means the experiment's default (the
        mean of its six sensors' temperatures).
    name : str
        Label of the experiment (output folder name); the file's stem by default.
    """

    file: Path
    t_ref_degC: float | None = None
    name: str = ""


@dataclass(frozen=True)
class Campaign:
    """A campaign manifest: which experiments calibrate one IMU, and how.

    Attributes
    ----------
    path : Path
        The manifest file (absolute).
    imu_id : str
    grade : str
        A key of :data:`graph_calib.params.GRADES`.
    experiments : tuple of CampaignExperiment
    priors : dict
        ``{parameter name: one-sigma prior}``, SI, overriding the grade's.
    effects : tuple of str
        Further effects (model.md) added to the declared model.
    exclude : tuple of str
        Declared parameters left out of the model (e.g. ``lever_arm`` without a table).
    solver : dict
        Solver options given in ``[solver]`` (see :data:`SOLVER_OPTIONS`); absent
        options take the solver's defaults.
    """

    path: Path
    imu_id: str
    grade: str
    experiments: tuple
    priors: dict = field(default_factory=dict)
    effects: tuple = ()
    exclude: tuple = ()
    solver: dict = field(default_factory=dict)

    def layout(self):
        """The :class:`~graph_calib.params.Layout` of the modelled parameters."""
        return params.Layout.declared(extra=self.effects, exclude=self.exclude)

    def prior_sigmas(self):
        """One-sigma priors per parameter name, SI: the grade's, overridden by ``priors``."""
        merged = dict(params.grade(self.grade).prior_sigma)
        merged.update(self.priors)
        return merged


def _unknown_keys(table, known, *, path, where):
    unknown = [k for k in table if k not in known]
    if unknown:
        raise InputError(f"unknown key {_show(unknown[0])}; known: {', '.join(known)}", path=path, dataset=where)


def _flatten_priors(table, prefix=""):
    """``{"gyro": {"bias": 1e-6}}`` (an unquoted dotted TOML key) -> ``{"gyro.bias": 1e-6}``."""
    out = {}
    for k, v in table.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten_priors(v, name + "."))
        else:
            out[name] = v
    return out


def _name_list(value, *, path, where):
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise InputError(f"must be a list of parameter names, got {_show(value)}", path=path, dataset=where)
    return tuple(dict.fromkeys(value))


def read_manifest(path):
    """Read and check a campaign manifest (TOML).

    The layout is that of ``data-format.md``; the further tables ``[priors]``,
    ``[model]`` and ``[solver]`` and the per-experiment ``name`` are defined in
    ``docs/data-format.md``.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Campaign

    Raises
    ------
    InputError
        One per problem, naming the manifest and the table or key: TOML syntax
        (with its line), missing ``[imu]``, ``id`` or ``grade``, unknown grade, no
        ``[[experiment]]``, an experiment without ``file`` or whose file does not
        exist, a non-numeric ``t_ref_degC``, an unknown parameter or a
        non-positive sigma in ``[priors]``, an unknown effect, an unknown key.
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path=path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"TOML syntax error: {exc}", path=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", path=path) from None
    _unknown_keys(doc, _MANIFEST_KEYS, path=path, where="top level")

    imu = doc.get("imu")
    if not isinstance(imu, dict):
        raise InputError("missing [imu] table", path=path, dataset="[imu]")
    _unknown_keys(imu, _IMU_KEYS, path=path, where="[imu]")
    imu_id = imu.get("id")
    if not isinstance(imu_id, str) or not imu_id:
        raise InputError("missing id (a string: IMU model and serial number)", path=path, dataset="[imu].id")
    grade = imu.get("grade")
    if grade is None:
        raise InputError(f"missing grade; known: {', '.join(params.GRADES)}", path=path, dataset="[imu].grade")
    if grade not in params.GRADES:
        raise InputError(f"unknown grade {_show(grade)}; known: {', '.join(params.GRADES)}", path=path,
                         dataset="[imu].grade")

    entries = doc.get("experiment")
    if not isinstance(entries, list) or not entries:
        raise InputError("no [[experiment]] given", path=path, dataset="[[experiment]]")
    experiments, names = [], set()
    for i, entry in enumerate(entries):
        where = f"[[experiment]] #{i + 1}"
        if not isinstance(entry, dict):
            raise InputError("must be a table", path=path, dataset=where)
        _unknown_keys(entry, _EXPERIMENT_KEYS, path=path, where=where)
        file = entry.get("file")
        if not isinstance(file, str) or not file:
            raise InputError("missing file", path=path, dataset=where)
        resolved = (path.parent / file).resolve()
        if not resolved.is_file():
            raise InputError(f"experiment file {resolved} not found", path=path, dataset=f"{where}.file")
        t_ref = entry.get("t_ref_degC")
        if t_ref is not None:
            if not _is_real(t_ref) or not math.isfinite(t_ref):
                raise InputError(f"t_ref_degC must be a number, got {_show(t_ref)}", path=path,
                                 dataset=f"{where}.t_ref_degC")
            t_ref = float(t_ref)
        name = entry.get("name", Path(file).stem)
        if not isinstance(name, str) or not name:
            raise InputError(f"name must be a non-empty string, got {_show(name)}", path=path, dataset=f"{where}.name")
        if name in names:
            raise InputError(f"name {_show(name)} used twice; give each experiment its own 'name'", path=path,
                             dataset=f"{where}.name")
        names.add(name)
        experiments.append(CampaignExperiment(file=resolved, t_ref_degC=t_ref, name=name))

    priors = {}
    raw_priors = doc.get("priors", {})
    if not isinstance(raw_priors, dict):
        raise InputError("must be a table", path=path, dataset="[priors]")
    for name, sigma in _flatten_priors(raw_priors).items():
        where = f'[priors]."{name}"'
        if name not in params.SPECS:
            hint = ""
            with contextlib.suppress(KeyError):
                hint = f" (priors are per parameter: use {_show(params.split_element_name(name)[0])})"
            raise InputError(f"unknown parameter {_show(name)}{hint}; known: {', '.join(params.SPECS)}",
                             path=path, dataset=where)
        if not _is_real(sigma) or not math.isfinite(sigma) or sigma <= 0:
            raise InputError(f"prior sigma must be a positive number (SI), got {_show(sigma)}", path=path, dataset=where)
        priors[name] = float(sigma)

    model = doc.get("model", {})
    if not isinstance(model, dict):
        raise InputError("must be a table", path=path, dataset="[model]")
    _unknown_keys(model, _MODEL_KEYS, path=path, where="[model]")
    effects = _name_list(model.get("effects", []), path=path, where="[model].effects")
    for name in effects:
        if name in params.DECLARED:
            raise InputError(f"{_show(name)} is already in the declared model", path=path, dataset="[model].effects")
        if name not in params.FURTHER_EFFECTS:
            raise InputError(f"unknown effect {_show(name)}; known: {', '.join(params.FURTHER_EFFECTS)}",
                             path=path, dataset="[model].effects")
    exclude = _name_list(model.get("exclude", []), path=path, where="[model].exclude")
    for name in exclude:
        if name not in params.DECLARED:
            raise InputError(f"{_show(name)} is not a declared parameter; known: {', '.join(params.DECLARED)}",
                             path=path, dataset="[model].exclude")

    solver = doc.get("solver", {})
    if not isinstance(solver, dict):
        raise InputError("must be a table", path=path, dataset="[solver]")
    _unknown_keys(solver, tuple(SOLVER_OPTIONS), path=path, where="[solver]")
    for key, value in solver.items():
        problem = SOLVER_OPTIONS[key][1](value)
        if problem:
            raise InputError(f"{problem}, got {_show(value)}", path=path, dataset=f"[solver].{key}")

    return Campaign(path=path, imu_id=imu_id, grade=grade, experiments=tuple(experiments), priors=priors,
                    effects=effects, exclude=exclude, solver=dict(solver))
