"""Experiment, result and manifest files: round trips, one test per validation rule, atomic writing."""

import json
import os
import re
from dataclasses import replace

import h5py
import numpy as np
import pytest

from graph_calib.sensors import params
from graph_calib.errors import InputError
from graph_calib.records.experiment import Result, Table
from graph_calib.io import (
    Campaign, atomic_path, atomic_write_json, atomic_write_text, dumps_json, read_experiment, read_manifest,
    read_result, validate_experiment, write_experiment, write_result,
)

# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def _assert_experiments_equal(a, b):
    for name in ("t", "dtheta", "dv", "temperature", "temperature_map"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        assert x.shape == y.shape, name
        assert np.array_equal(x, y), name
    for name in ("temperature_names", "rate_hz", "latitude_rad", "gravity_mps2", "imu_id", "description"):
        assert getattr(a, name) == getattr(b, name), name
        assert type(getattr(a, name)) is type(getattr(b, name)), name
    assert (a.segment is None) == (b.segment is None)
    if a.segment is not None:
        assert np.array_equal(a.segment, b.segment)
    assert (a.table is None) == (b.table is None)
    if a.table is not None:
        for name in ("t", "q_nf", "valid", "q_fb_nominal"):
            x, y = getattr(a.table, name), getattr(b.table, name)
            assert x.dtype == y.dtype and np.array_equal(x, y), f"table.{name}"


def _replace_dataset(f, name, data):
    """Replace dataset ``name`` by ``data`` keeping its attributes."""
    attrs = {}
    for k, v in f[name].attrs.items():
        if isinstance(v, np.ndarray) and v.dtype.kind == "O":
            v = np.array(v.tolist(), dtype=h5py.string_dtype())
        attrs[k] = v
    del f[name]
    f[name] = data
    for k, v in attrs.items():
        f[name].attrs[k] = v


def _edit(name, fn):
    """Corruption: read dataset ``name``, apply ``fn`` (returns the new data), write it back."""
    return lambda f: _replace_dataset(f, name, fn(f[name][()]))


def _set_attr(obj, name, value):
    return lambda f: f[obj].attrs.__setitem__(name, value)


def _del_attr(obj, name):
    return lambda f: f[obj].attrs.__delitem__(name)


def _delete(name):
    return lambda f: f.__delitem__(name)


def _at(i, fn):
    """Array edit applied at row ``i`` (a copy is returned)."""
    def edit(a):
        a = a.copy()
        a[i] = fn(a[i])
        return a
    return edit


def _t_to_group(f):
    del f["imu/t"]
    f["imu"].create_group("t")


def _gap(a):
    a = a.copy()
    a[300:] += 0.05
    return a


def _segment(values):
    """Corruption: add ``/imu/segment`` holding ``values`` (600 samples)."""
    return lambda f: f["imu"].create_dataset("segment", data=values)


def _segment_and_gap(f):
    """Segments 0 | 1 cut at sample 200, a gap at sample 300 (inside segment 1)."""
    _segment(np.repeat(np.array([0, 1], dtype=np.int32), [200, 400]))(f)
    _replace_dataset(f, "imu/t", _gap(f["imu/t"][()]))


@pytest.fixture
def good_file(tmp_path, experiment_factory):
    path = tmp_path / "exp.h5"
    write_experiment(experiment_factory(), path)
    return path


# ---------------------------------------------------------------------------
# experiment file: round trip and accepted variants
# ---------------------------------------------------------------------------


def test_experiment_round_trip_is_exact(tmp_path, experiment_factory):
    exp = experiment_factory()
    path = tmp_path / "exp.h5"
    write_experiment(exp, path)
    back = read_experiment(path)
    _assert_experiments_equal(exp, back)
    assert back.source == str(path)
    with h5py.File(path, "r") as f:  # the file itself has the layout of data-format.md
        assert f.attrs["format"] == "imu-calibration-experiment" and f.attrs["version"] == 1
        assert f["imu/t"].dtype == np.float64 and f["imu/dtheta"].shape == (600, 3)
        assert list(f["imu/temperature"].attrs["names"]) == ["gyro_block", "accel_block"]
        assert f["table/valid"].dtype == bool


def test_experiment_round_trip_without_table(tmp_path, experiment_factory):
    exp = experiment_factory(with_table=False)
    path = tmp_path / "exp.h5"
    write_experiment(exp, path)
    back = read_experiment(path)
    _assert_experiments_equal(exp, back)
    with h5py.File(path, "r") as f:
        assert "table" not in f


def _three_pieces(experiment_factory):
    """The factory's record cut into segments 0, 1 and 4 at samples 200 and 300, with a gap at each cut."""
    exp = experiment_factory(with_table=False)
    t = exp.t.copy()
    t[200:] += 5.0
    t[300:] += 0.5
    segment = np.repeat(np.array([0, 1, 4], dtype=np.int32), [200, 100, 300])
    return replace(exp, t=t, segment=segment)


def test_experiment_round_trip_with_segments(tmp_path, experiment_factory):
    exp = _three_pieces(experiment_factory)
    path = tmp_path / "exp.h5"
    write_experiment(exp, path)
    back = read_experiment(path)
    _assert_experiments_equal(exp, back)
    assert back.segment.dtype == np.int32 and np.array_equal(back.segment, exp.segment)
    with h5py.File(path, "r") as f:
        assert f["imu/segment"].dtype == np.int32 and f["imu/segment"].shape == (600,)
    assert back.n_segments == 3 and back.segment_bounds() == [(0, 200), (200, 300), (300, 600)]


def test_gaps_at_segment_boundaries_are_accepted(tmp_path, experiment_factory):
    """The same gaps that are refused without /imu/segment are accepted where the segment changes."""
    exp = _three_pieces(experiment_factory)
    with pytest.raises(InputError, match=r"/imu/t \[sample 200\]: gap of 5\.01 s \(501 nominal periods\)"):
        validate_experiment(replace(exp, segment=None), path="memory")
    validate_experiment(exp, path="memory")  # no exception
    path = tmp_path / "exp.h5"
    write_experiment(exp, path)
    assert read_experiment(path).n_segments == 3


def test_without_segment_a_record_is_one_segment(good_file):
    exp = read_experiment(good_file)
    with h5py.File(good_file, "r") as f:
        assert "segment" not in f["imu"]
    assert exp.segment is None and exp.n_segments == 1 and exp.segment_bounds() == [(0, 600)]


def test_integer_segment_types_are_read_as_int32(good_file):
    with h5py.File(good_file, "r+") as f:
        f["imu"].create_dataset("segment", data=np.repeat(np.array([3, 7], dtype=np.int64), [300, 300]))
    exp = read_experiment(good_file)
    assert exp.segment.dtype == np.int32 and exp.n_segments == 2


def test_first_sample_of_a_segment_covers_one_nominal_period(experiment_factory):
    exp = _three_pieces(experiment_factory)
    dt = exp.dt
    assert dt[0] == dt[200] == dt[300] == 1.0 / exp.rate_hz
    assert dt[199] == pytest.approx(0.01) and dt[201] == pytest.approx(0.01)


def test_slice_keeps_the_segments(experiment_factory):
    exp = _three_pieces(experiment_factory).slice(150, 350)
    assert np.array_equal(exp.segment, np.repeat([0, 1, 4], [50, 100, 50])) and exp.n_segments == 3


def test_write_refuses_decreasing_segments_and_writes_nothing(tmp_path, experiment_factory):
    exp = _three_pieces(experiment_factory)
    bad = replace(exp, segment=exp.segment[::-1].copy())
    path = tmp_path / "exp.h5"
    with pytest.raises(InputError, match=re.escape(f"{path}: /imu/segment [sample 300]: segment 1 after segment 4")):
        write_experiment(bad, path)
    assert not path.exists()


def test_float32_datasets_are_upcast(good_file):
    with h5py.File(good_file, "r+") as f:
        ref = f["imu/dv"][()].astype(np.float32)
        _replace_dataset(f, "imu/dv", ref)
    exp = read_experiment(good_file)
    assert exp.dv.dtype == np.float64
    assert np.array_equal(exp.dv, ref.astype(np.float64))


def test_defaults_of_optional_attributes(good_file):
    with h5py.File(good_file, "r+") as f:
        del f["imu"].attrs["temperature_map"]
        del f["table"].attrs["q_fb_nominal"]
        del f.attrs["description"]
    exp = read_experiment(good_file)
    assert np.array_equal(exp.temperature_map, np.zeros(6, dtype=np.int64))
    assert np.array_equal(exp.table.q_fb_nominal, [1.0, 0.0, 0.0, 0.0])
    assert exp.description == ""


def test_one_element_array_attributes_count_as_scalars(good_file):
    with h5py.File(good_file, "r+") as f:  # as MATLAB writes scalar attributes
        f.attrs["latitude_rad"] = np.array([[0.95]])
        f.attrs["version"] = np.array([1], dtype=np.int32)
        f["imu"].attrs["rate_hz"] = np.array([100.0], dtype=np.float32)
        f.attrs["imu_id"] = np.array([b"TEST-IMU 0001"])
    exp = read_experiment(good_file)
    assert exp.latitude_rad == 0.95 and exp.rate_hz == 100.0 and exp.imu_id == "TEST-IMU 0001"
    assert type(exp.rate_hz) is float


def test_table_readings_outside_the_imu_span_and_truth_group_are_accepted(good_file):
    with h5py.File(good_file, "r+") as f:
        _replace_dataset(f, "table/t", f["table/t"][()] + 50.0)  # mostly after the last IMU sample
        f.create_group("truth")
    exp = read_experiment(good_file)
    assert exp.table.t[-1] > exp.t[-1]


# ---------------------------------------------------------------------------
# experiment file: one test per rule
# ---------------------------------------------------------------------------

ROOT = '/.attrs["{}"]'
RULES = [
    # (id, corruption, dataset named, sample index or None, message pattern)
    ("format-missing", _del_attr("/", "format"), ROOT.format("format"), None, "missing attribute"),
    ("format-wrong", _set_attr("/", "format", "imu-log"), ROOT.format("format"), None, "format is 'imu-log'"),
    ("version-unsupported", _set_attr("/", "version", np.int64(2)), ROOT.format("version"), None,
     "version 2 is not supported"),
    ("version-not-integer", _set_attr("/", "version", 1.0), ROOT.format("version"), None,
     "must be the integer 1, got float 1.0"),
    ("version-text", _set_attr("/", "version", "1"), ROOT.format("version"), None, "must be the integer 1, got str '1'"),
    ("latitude-missing", _del_attr("/", "latitude_rad"), ROOT.format("latitude_rad"), None, "missing attribute"),
    ("latitude-degrees", _set_attr("/", "latitude_rad", 45.4), ROOT.format("latitude_rad"), None,
     r"beyond \[-pi/2, pi/2\]; it looks like degrees"),
    ("latitude-not-finite", _set_attr("/", "latitude_rad", np.nan), ROOT.format("latitude_rad"), None,
     "must be a finite number"),
    ("gravity-missing", _del_attr("/", "gravity_mps2"), ROOT.format("gravity_mps2"), None, "missing attribute"),
    ("gravity-g-units", _set_attr("/", "gravity_mps2", 1.0), ROOT.format("gravity_mps2"), None,
     "looks like g units"),
    ("gravity-implausible", _set_attr("/", "gravity_mps2", 12.0), ROOT.format("gravity_mps2"), None,
     r"outside \[9.7, 9.9\], implausible"),
    ("imu-id-missing", _del_attr("/", "imu_id"), ROOT.format("imu_id"), None, "missing attribute"),
    ("imu-id-not-string", _set_attr("/", "imu_id", 7), ROOT.format("imu_id"), None, "must be a string"),
    ("imu-group-missing", _delete("imu"), "/imu", None, "missing group"),
    ("dataset-missing", _delete("imu/dv"), "/imu/dv", None, "missing dataset"),
    ("dataset-is-group", _t_to_group, "/imu/t", None, "is a group, expected a dataset"),
    ("t-shape", _edit("imu/t", lambda a: a[:, None]), "/imu/t", None, r"shape \(600, 1\), expected \(N,\)"),
    ("dtheta-shape", _edit("imu/dtheta", lambda a: a[:, :2]), "/imu/dtheta", None,
     r"shape \(600, 2\), expected \(600, 3\)"),
    ("dv-length", _edit("imu/dv", lambda a: a[:-1]), "/imu/dv", None, r"shape \(599, 3\), expected \(600, 3\)"),
    ("temperature-shape", _edit("imu/temperature", lambda a: a[:, 0]), "/imu/temperature", None,
     r"shape \(600,\), expected \(600, K\)"),
    ("t-dtype", _edit("imu/t", lambda a: np.arange(600, dtype=np.int64)), "/imu/t", None,
     "dtype int64 is not floating point"),
    ("dtheta-dtype", _edit("imu/dtheta", lambda a: (a * 1e9).astype(np.int32)), "/imu/dtheta", None,
     "dtype int32 is not floating point"),
    ("t-nan", _edit("imu/t", _at(5, lambda v: np.nan)), "/imu/t", 5, "NaN"),
    ("dv-nan", _edit("imu/dv", _at(123, lambda v: [0.0, np.nan, 0.0])), "/imu/dv", 123, "NaN"),
    ("temperature-inf", _edit("imu/temperature", _at(77, lambda v: [np.inf, 20.0])), "/imu/temperature", 77,
     "infinite value"),
    ("t-not-increasing", _edit("imu/t", _at(40, lambda v: v - 0.01)), "/imu/t", 40, "not strictly increasing"),
    ("t-gap", _edit("imu/t", _gap), "/imu/t", 300,
     (r"gap of 0\.06 s \(6 nominal periods\) before this sample; at most 3 periods are accepted inside a "
      r"segment: mark where the pieces start in /imu/segment")),
    ("t-gap-inside-segment", _segment_and_gap, "/imu/t", 300,
     r"gap of 0\.06 s \(6 nominal periods\) before this sample inside segment 1; at most 3 periods"),
    ("segment-decreasing", _segment(np.repeat(np.array([0, 1, 0], dtype=np.int32), [100, 100, 400])),
     "/imu/segment", 200, "segment 0 after segment 1: segments must be non-decreasing"),
    ("segment-dtype", _segment(np.zeros(600)), "/imu/segment", None, "dtype float64 is not an integer type"),
    ("segment-shape", _segment(np.zeros(599, dtype=np.int32)), "/imu/segment", None,
     r"shape \(599,\), expected \(600,\)"),
    ("segment-beyond-int32", _segment(np.repeat(np.array([0, 2**31], dtype=np.int64), [10, 590])),
     "/imu/segment", 10, "segment 2147483648 does not fit the file's int32"),
    ("segment-is-group", lambda f: f["imu"].create_group("segment"), "/imu/segment", None,
     "is a group, expected a dataset"),
    ("rate-missing", _del_attr("imu", "rate_hz"), '/imu.attrs["rate_hz"]', None, "missing attribute"),
    ("rate-not-positive", _set_attr("imu", "rate_hz", -100.0), '/imu.attrs["rate_hz"]', None,
     "must be a positive finite number"),
    ("rate-inconsistent", _set_attr("imu", "rate_hz", 112.0), '/imu.attrs["rate_hz"]', None,
     r"disagrees with the median sample spacing 0\.01 s \(100 Hz\)"),
    ("names-missing", _del_attr("imu/temperature", "names"), '/imu/temperature.attrs["names"]', None,
     "missing attribute"),
    ("names-length", _set_attr("imu/temperature", "names", np.array(["a"], dtype=h5py.string_dtype())),
     '/imu/temperature.attrs["names"]', None, "1 name\\(s\\) for K = 2 temperature channel\\(s\\)"),
    ("map-out-of-range", _set_attr("imu", "temperature_map", np.array([0, 0, 0, 2, 1, 1])),
     '/imu.attrs["temperature_map"]', None, r"channel 2 for sensor 3 .* is not in \[0, 2\)"),
    ("map-length", _set_attr("imu", "temperature_map", np.array([0, 0, 0, 1, 1])),
     '/imu.attrs["temperature_map"]', None, r"shape \(5,\), expected \(6,\)"),
    ("map-not-integer", _set_attr("imu", "temperature_map", np.zeros(6)), '/imu.attrs["temperature_map"]', None,
     "not an integer type"),
    ("temperature-kelvin", _edit("imu/temperature", lambda a: a + 273.15), "/imu/temperature", 0,
     "looks like Kelvin"),
    ("dtheta-degrees", _edit("imu/dtheta", lambda a: np.degrees(a)), "/imu/dtheta", 300,
     r"exceeds 35 rad/s \(2005 deg/s\): degrees written for radians"),
    ("dtheta-rates", _edit("imu/dtheta", lambda a: a * 100.0), "/imu/dtheta", 300,
     "or rates written for increments"),
    ("dv-rates", _edit("imu/dv", lambda a: a * 100.0), "/imu/dv", 0, "exceeds 16 g"),
    ("dv-spike", _edit("imu/dv", _at(10, lambda v: [0.0, 0.0, 2.0])), "/imu/dv", 10,
     r"\|dv\| / dt = 200 m/s\^2 exceeds 16 g"),
    ("dv-g-units", _edit("imu/dv", lambda a: a / 9.8), "/imu/dv", None,
     r"median \|dv\| / dt over the record is 1 m/s\^2, outside \[0.5, 2\] x gravity"),
    ("table-dataset-missing", _delete("table/q_nf"), "/table/q_nf", None, "missing dataset"),
    ("table-t-nan", _edit("table/t", _at(5, lambda v: np.nan)), "/table/t", 5, "NaN"),
    ("table-t-not-increasing", _edit("table/t", _at(3, lambda v: v - 0.2)), "/table/t", 3,
     "not strictly increasing"),
    ("table-q-shape", _edit("table/q_nf", lambda a: a[:, :3]), "/table/q_nf", None,
     r"shape \(60, 3\), expected \(60, 4\)"),
    ("table-q-not-unit", _edit("table/q_nf", _at(7, lambda v: v * 1.00001)), "/table/q_nf", 7,
     "quaternion norm 1.00001.* is not 1"),
    ("table-valid-dtype", _edit("table/valid", lambda a: a.astype(np.int8)), "/table/valid", None,
     "dtype int8 is not bool"),
    ("table-valid-shape", _edit("table/valid", lambda a: a[:-1]), "/table/valid", None,
     r"shape \(59,\), expected \(60,\)"),
    ("q-fb-shape", _set_attr("table", "q_fb_nominal", np.array([1.0, 0.0, 0.0])), '/table.attrs["q_fb_nominal"]',
     None, r"shape \(3,\), expected \(4,\)"),
    ("q-fb-not-unit", _set_attr("table", "q_fb_nominal", np.array([1.0, 0.1, 0.0, 0.0])),
     '/table.attrs["q_fb_nominal"]', None, "quaternion norm .* is not 1"),
]


@pytest.mark.parametrize("corrupt, dataset, index, pattern", [r[1:] for r in RULES], ids=[r[0] for r in RULES])
def test_each_rule_refuses_a_breaking_file(good_file, corrupt, dataset, index, pattern):
    with h5py.File(good_file, "r+") as f:
        corrupt(f)
    with pytest.raises(InputError, match=pattern) as info:
        read_experiment(good_file)
    message = str(info.value)
    assert message.startswith(f"{good_file}: {dataset}"), message
    assert info.value.path == good_file and info.value.dataset == dataset
    if index is None:
        assert "[sample" not in message
    else:
        assert f"{dataset} [sample {index}]:" in message
        assert info.value.index == index
    assert "\n" not in message


def test_missing_file_is_refused(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_experiment(tmp_path / "nope.h5")


def test_non_hdf5_file_is_refused(tmp_path):
    path = tmp_path / "exp.h5"
    path.write_text("t,gx\n")
    with pytest.raises(InputError, match=re.escape(f"{path}: not a readable HDF5 file")):
        read_experiment(path)


# ---------------------------------------------------------------------------
# writing: validation first, atomic
# ---------------------------------------------------------------------------


def test_write_validates_and_leaves_no_file(tmp_path, experiment_factory):
    exp = experiment_factory()
    bad = replace(exp, latitude_rad=52.0)
    path = tmp_path / "exp.h5"
    with pytest.raises(InputError, match="looks like degrees"):
        write_experiment(bad, path)
    assert list(tmp_path.iterdir()) == []


def test_write_validates_table_in_memory(tmp_path, experiment_factory):
    exp = experiment_factory()
    q = exp.table.q_nf.copy()
    q[4] *= 2.0
    bad = replace(exp, table=Table(exp.table.t, q, exp.table.valid, exp.table.q_fb_nominal))
    with pytest.raises(InputError, match=r"/table/q_nf \[sample 4\]: quaternion norm 2"):
        write_experiment(bad, tmp_path / "exp.h5")


def test_failed_write_leaves_nothing_behind_and_keeps_the_old_file(tmp_path, experiment_factory, monkeypatch):
    path = tmp_path / "exp.h5"
    write_experiment(experiment_factory(seed=1), path)
    before = path.read_bytes()
    calls = []

    def failing_create_dataset(self, *args, **kwargs):
        calls.append(args[0])
        if len(calls) == 3:
            raise OSError("disk full (simulated)")
        return original(self, *args, **kwargs)

    original = h5py.Group.create_dataset
    monkeypatch.setattr(h5py.Group, "create_dataset", failing_create_dataset)
    with pytest.raises(OSError, match="disk full"):
        write_experiment(experiment_factory(seed=2), path)
    assert [p.name for p in tmp_path.iterdir()] == ["exp.h5"]  # no temporary file left
    assert path.read_bytes() == before
    new = tmp_path / "new.h5"
    calls.clear()
    with pytest.raises(OSError, match="disk full"):
        write_experiment(experiment_factory(seed=2), new)
    assert not new.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["exp.h5"]


def test_atomic_path_removes_the_temporary_file_on_error(tmp_path):
    target = tmp_path / "out.txt"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            assert tmp.parent == tmp_path and tmp != target
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []


def test_atomic_write_text_replaces_and_sets_normal_permissions(tmp_path):
    target = tmp_path / "out.txt"
    atomic_write_text(target, "one")
    atomic_write_text(target, "two")
    assert target.read_text() == "two"
    assert target.stat().st_mode & 0o777 == 0o666 & ~_umask()
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_atomic_write_refuses_a_missing_folder(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        atomic_write_text(tmp_path / "no" / "out.txt", "x")


def test_atomic_write_json_is_numpy_safe_and_exact(tmp_path):
    obj = {"a": np.float32(0.1), "b": np.arange(3), "c": np.array([[0.1 + 0.2, 1e-300]]), "d": np.bool_(True),
           "e": (1, 2), "f": np.int64(7), "g": 5e-324}
    path = tmp_path / "x.json"
    atomic_write_json(path, obj)
    back = json.loads(path.read_text())
    assert back == {"a": float(np.float32(0.1)), "b": [0, 1, 2], "c": [[0.30000000000000004, 1e-300]], "d": True,
                    "e": [1, 2], "f": 7, "g": 5e-324}
    with pytest.raises(ValueError):
        atomic_write_json(tmp_path / "nan.json", {"x": float("nan")})
    assert not (tmp_path / "nan.json").exists()


# ---------------------------------------------------------------------------
# result file
# ---------------------------------------------------------------------------


def _result(solver="sqrt-kf", *, covariance=True, seed=3):
    rng = np.random.default_rng(seed)
    names = ("gyro.bias.x", "gyro.bias.y", "gyro.bias.z", "accel.misalignment.zy", "time_lag.table")
    values = dict(zip(names, [1.2e-8, 0.1 + 0.2, -3.3e-300, 5e-324, 0.004]))
    sigmas = dict(zip(names, rng.uniform(0.1, 1.0, 5) * np.array([1e-9, 1e-9, 1e-9, 1e-5, 1e-3])))
    cov = None
    if covariance:
        a = rng.normal(size=(5, 5)) * np.array(list(sigmas.values()))
        cov = a.T @ a
        cov = 0.5 * (cov + cov.T)
    return Result(
        source="sub1_20_30.h5", solver=solver, t_ref_degC=25.000000000000004,
        temperature_range_degC=(20.1, 29.8), effects=("gyro.bias", "accel.misalignment", "time_lag.table"),
        values=values, sigmas=None if solver == "truth" else sigmas,
        covariance_names=names if covariance else None, covariance=cov,
        residuals={"gravity_rms_mps2": 1.1e-5, "iterations": 7, "per_axis": [0.1, 0.2, 0.3]},
        extra={"priors": {"gyro.bias": 1e-6}, "options": {"keyframe_s": 1.0}},
    )


def test_result_round_trip_is_exact(tmp_path):
    res = _result()
    path = tmp_path / "sqrt-kf.json"
    write_result(res, path)
    back = read_result(path)
    for name in ("source", "solver", "t_ref_degC", "temperature_range_degC", "effects", "values", "sigmas",
                 "covariance_names", "residuals", "extra"):
        assert getattr(back, name) == getattr(res, name), name
    assert back.covariance.dtype == np.float64 and np.array_equal(back.covariance, res.covariance)
    doc = json.loads(path.read_text())
    assert list(doc) == ["format", "version", "source", "solver", "t_ref_degC", "temperature_range_degC", "effects",
                         "estimates", "covariance", "residuals", "priors", "options"]
    assert doc["format"] == "imu-calibration-result" and doc["version"] == 1
    assert doc["estimates"]["gyro.bias.x"] == {"value": 1.2e-8, "sigma": res.sigmas["gyro.bias.x"]}
    assert doc["covariance"]["names"] == list(res.covariance_names)


def test_truth_round_trip_has_no_sigma_and_no_covariance(tmp_path):
    res = _result("truth", covariance=False)
    path = tmp_path / "sub1.truth.json"
    write_result(res, path)
    doc = json.loads(path.read_text())
    assert all(set(e) == {"value"} for e in doc["estimates"].values())
    assert "covariance" not in doc
    back = read_result(path)
    assert back.sigmas is None and back.covariance is None and back.covariance_names is None
    assert back.values == res.values


def test_write_result_refuses_a_missing_sigma(tmp_path):
    res = _result()
    sig = dict(res.sigmas)
    del sig["gyro.bias.y"]
    path = tmp_path / "r.json"
    with pytest.raises(InputError, match=re.escape(f'{path}: estimates["gyro.bias.y"].sigma: missing sigma')):
        write_result(replace(res, sigmas=sig), path)
    assert not path.exists()


def _doc_edit(fn):
    def edit(doc):
        fn(doc)
        return doc
    return edit


RESULT_RULES = [
    ("format", _doc_edit(lambda d: d.update(format="imu-calibration-experiment")), "format",
     "format is 'imu-calibration-experiment'"),
    ("version", _doc_edit(lambda d: d.update(version=2)), "version", "version 2 is not supported"),
    ("missing-key", _doc_edit(lambda d: d.pop("t_ref_degC")), "t_ref_degC", "missing key"),
    ("unknown-element", _doc_edit(lambda d: d["estimates"].update({"gyro.bias.w": {"value": 1.0, "sigma": 1.0}})),
     'estimates["gyro.bias.w"]', "unknown parameter element 'gyro.bias.w'"),
    ("missing-sigma", _doc_edit(lambda d: d["estimates"]["time_lag.table"].pop("sigma")),
     'estimates["time_lag.table"].sigma', "missing sigma"),
    ("negative-sigma", _doc_edit(lambda d: d["estimates"]["time_lag.table"].update(sigma=-1.0)),
     'estimates["time_lag.table"].sigma', "negative sigma"),
    ("value-not-number", _doc_edit(lambda d: d["estimates"]["gyro.bias.x"].update(value="1e-8")),
     'estimates["gyro.bias.x"].value', "must be a finite number"),
    ("unknown-effect", _doc_edit(lambda d: d["effects"].append("gyro.wobble")), "effects",
     "unknown parameter 'gyro.wobble'"),
    ("covariance-not-square", _doc_edit(lambda d: d["covariance"]["matrix"].pop()), "covariance.matrix",
     r"square 5 x 5 .* got shape \(4, 5\)"),
    ("covariance-names", _doc_edit(lambda d: d["covariance"]["names"].pop()), "covariance.matrix",
     "matching the 4 names"),
    ("covariance-unknown-name", _doc_edit(lambda d: d["covariance"]["names"].__setitem__(0, "mount.w")),
     "covariance.names", "unknown parameter element 'mount.w'"),
    ("covariance-asymmetric", _doc_edit(lambda d: d["covariance"]["matrix"][0].__setitem__(1, 1.0)),
     "covariance.matrix", r"not symmetric: element \(0, 1\)"),
    ("temperature-range", _doc_edit(lambda d: d.update(temperature_range_degC=[30.0, 20.0])),
     "temperature_range_degC", "low 30.0 above high 20.0"),
]


@pytest.mark.parametrize("edit, key, pattern", [r[1:] for r in RESULT_RULES], ids=[r[0] for r in RESULT_RULES])
def test_each_result_rule_refuses_a_breaking_file(tmp_path, edit, key, pattern):
    path = tmp_path / "r.json"
    write_result(_result(), path)
    path.write_text(json.dumps(edit(json.loads(path.read_text()))))
    with pytest.raises(InputError, match=pattern) as info:
        read_result(path)
    assert str(info.value).startswith(f"{path}: {key}: ")


def test_truth_with_sigma_is_refused(tmp_path):
    path = tmp_path / "t.json"
    write_result(_result("truth"), path)
    doc = json.loads(path.read_text())
    doc["estimates"]["gyro.bias.x"]["sigma"] = 1.0
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=re.escape('estimates["gyro.bias.x"].sigma: a truth file has no sigma')):
        read_result(path)


def test_non_finite_numbers_and_bad_json_are_refused(tmp_path):
    path = tmp_path / "r.json"
    write_result(_result(), path)
    text = path.read_text()
    path.write_text(text.replace('"iterations": 7', '"iterations": NaN'))
    with pytest.raises(InputError, match="NaN is not a finite number"):
        read_result(path)
    lines = text.splitlines()
    lines[3] = lines[3].rstrip(",")  # drop a comma on line 4
    path.write_text("\n".join(lines))
    with pytest.raises(InputError, match=re.escape(f"{path}: JSON syntax error at line 5")):
        read_result(path)


# ---------------------------------------------------------------------------
# campaign manifest
# ---------------------------------------------------------------------------

GOOD_MANIFEST = """\
[imu]
id = "BINS-RT 0001"
grade = "navigation"

[[experiment]]
file = "sub1_20_30.h5"
t_ref_degC = 25

[[experiment]]
file = "data/sub2_30_40.h5"
name = "second"

[priors]
"gyro.bias" = 1e-6
accel.bias_tc = 2e-4

[model]
effects = ["gyro.bias_tc2", "accel.bias_dtdt"]
exclude = ["lever_arm"]

[solver]
keyframe_s = 0.5
solvers = "both"
max_iterations = 20
"""


@pytest.fixture
def campaign_dir(tmp_path, experiment_factory):
    (tmp_path / "data").mkdir()
    write_experiment(experiment_factory(), tmp_path / "sub1_20_30.h5")
    write_experiment(experiment_factory(seed=1), tmp_path / "data" / "sub2_30_40.h5")
    return tmp_path


def test_manifest_is_read(campaign_dir):
    path = campaign_dir / "campaign.toml"
    path.write_text(GOOD_MANIFEST)
    camp = read_manifest(path)
    assert isinstance(camp, Campaign)
    assert camp.path == path.resolve() and camp.imu_id == "BINS-RT 0001" and camp.grade == "navigation"
    assert [e.file for e in camp.experiments] == [(campaign_dir / "sub1_20_30.h5").resolve(),
                                                   (campaign_dir / "data" / "sub2_30_40.h5").resolve()]
    assert [e.t_ref_degC for e in camp.experiments] == [25.0, None]
    assert isinstance(camp.experiments[0].t_ref_degC, float)
    assert [e.name for e in camp.experiments] == ["sub1_20_30", "second"]
    assert camp.priors == {"gyro.bias": 1e-6, "accel.bias_tc": 2e-4}
    assert camp.effects == ("gyro.bias_tc2", "accel.bias_dtdt")
    assert camp.exclude == ("lever_arm",)
    assert camp.solver == {"keyframe_s": 0.5, "solvers": "both", "max_iterations": 20}
    layout = camp.layout()
    assert "gyro.bias_tc2" in layout and "lever_arm" not in layout
    sig = camp.prior_sigmas()
    assert sig["gyro.bias"] == 1e-6 and sig["mount"] == params.GRADES["navigation"].prior_sigma["mount"]
    assert read_experiment(camp.experiments[1].file).n_samples == 600


MANIFEST_RULES = [
    ("toml-syntax", lambda s: s.replace('id = "BINS-RT 0001"', 'id = "BINS-RT 0001'), None,
     r"TOML syntax error: .*line 2"),
    ("imu-missing", lambda s: s.replace('[imu]\nid = "BINS-RT 0001"\ngrade = "navigation"\n', ""), "[imu]",
     r"missing \[imu\] table"),
    ("id-missing", lambda s: s.replace('id = "BINS-RT 0001"\n', ""), "[imu].id", "missing id"),
    ("grade-unknown", lambda s: s.replace('"navigation"', '"automotive"'), "[imu].grade",
     "unknown grade 'automotive'; known: navigation, tactical, consumer"),
    ("no-experiment", lambda s: s.split("[[experiment]]")[0] + "[priors]\n", "[[experiment]]",
     r"no \[\[experiment\]\] given"),
    ("experiment-without-file", lambda s: s.replace('file = "data/sub2_30_40.h5"\n', ""), "[[experiment]] #2",
     "missing file"),
    ("experiment-file-missing", lambda s: s.replace("sub2_30_40.h5", "sub9.h5"), "[[experiment]] #2.file",
     r"experiment file .*sub9\.h5 not found"),
    ("experiment-file-a-number", lambda s: s.replace('"data/sub2_30_40.h5"', "5"), "[[experiment]] #2.file",
     "must be the experiment file's path as a string, got 5"),
    ("experiment-file-a-folder", lambda s: s.replace('"data/sub2_30_40.h5"', '"data"'), "[[experiment]] #2.file",
     r"experiment file .*data is a folder"),
    ("t-ref-not-number", lambda s: s.replace("t_ref_degC = 25", 't_ref_degC = "25"'), "[[experiment]] #1.t_ref_degC",
     "t_ref_degC must be a number"),
    ("prior-unknown", lambda s: s.replace('"gyro.bias" = 1e-6', '"gyro.drift" = 1e-6'), '[priors]."gyro.drift"',
     "unknown parameter 'gyro.drift'"),
    ("prior-element", lambda s: s.replace('"gyro.bias" = 1e-6', '"gyro.bias.x" = 1e-6'), '[priors]."gyro.bias.x"',
     "priors are per parameter: use 'gyro.bias'"),
    ("prior-not-positive", lambda s: s.replace('"gyro.bias" = 1e-6', '"gyro.bias" = 0.0'), '[priors]."gyro.bias"',
     "prior sigma must be a positive number"),
    ("effect-unknown", lambda s: s.replace('"accel.bias_dtdt"', '"accel.wobble"'), "[model].effects",
     "unknown effect 'accel.wobble'"),
    ("effect-declared", lambda s: s.replace('"accel.bias_dtdt"', '"accel.bias"'), "[model].effects",
     "'accel.bias' is already in the declared model"),
    ("top-level-unknown", lambda s: s + "\n[output]\nplots = true\n", "top level", "unknown key 'output'"),
    ("solver-option-unknown", lambda s: s.replace("keyframe_s", "key_frame_s"), "[solver]",
     "unknown key 'key_frame_s'"),
    ("solver-option-value", lambda s: s.replace("keyframe_s = 0.5", "keyframe_s = -1.0"), "[solver].keyframe_s",
     "must be a positive number"),
    ("duplicate-name", lambda s: s.replace('name = "second"', 'name = "sub1_20_30"'), "[[experiment]] #2.name",
     "used twice"),
    ("name-a-path", lambda s: s.replace('name = "second"', 'name = "../../escaped"'), "[[experiment]] #2.name",
     "one folder name, without a path separator"),
    ("name-hidden", lambda s: s.replace('name = "second"', 'name = ".."'), "[[experiment]] #2.name",
     "not starting with '.'"),
]


@pytest.mark.parametrize("edit, where, pattern", [r[1:] for r in MANIFEST_RULES], ids=[r[0] for r in MANIFEST_RULES])
def test_each_manifest_rule_refuses_a_breaking_manifest(campaign_dir, edit, where, pattern):
    path = campaign_dir / "campaign.toml"
    path.write_text(edit(GOOD_MANIFEST))
    with pytest.raises(InputError, match=pattern) as info:
        read_manifest(path)
    message = str(info.value)
    prefix = f"{path.resolve()}: " + (f"{where}: " if where else "")
    assert message.startswith(prefix), message
    assert "\n" not in message


def test_manifest_minimal_from_the_spec(campaign_dir):
    path = campaign_dir / "campaign.toml"
    path.write_text('[imu]\nid = "X 1"\ngrade = "consumer"\n\n[[experiment]]\nfile = "sub1_20_30.h5"\n')
    camp = read_manifest(path)
    assert camp.priors == {} and camp.effects == () and camp.exclude == () and camp.solver == {}
    assert camp.experiments[0].t_ref_degC is None


def test_validate_experiment_accepts_the_factory(experiment_factory):
    validate_experiment(experiment_factory(), path="memory")  # no exception


def test_dumps_json_keeps_rows_on_one_line():
    text = dumps_json({"covariance": {"names": ["a", "b"], "matrix": np.eye(2)}})
    assert '"matrix": [\n      [1.0, 0.0],\n      [0.0, 1.0]\n    ]' in text
