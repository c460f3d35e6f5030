"""Property-based tests (hypothesis) of every reader and importer: bad input is refused, never crashed on.

For random corruptions of valid files and of CSV text, each reader either reads the file (a corruption may
leave it valid) or raises :class:`~graph_calib.errors.InputError` whose message is one line naming the file
(cli.md: exit 2, one line, no traceback); any other exception fails the property.  The ``import`` command
exits 0 or 2 (never 1), and on 2 leaves no output file and no temporary file behind; what it writes, the
experiment reader reads back.

Readers: ``io.read_experiment`` (valid files from ``io.write_experiment`` mutated with h5py, and bytes
overwritten), ``io.read_result`` (mutated JSON), ``io.read_manifest`` (mutated TOML), the importers
(``import_csv`` on random text and columns and on mutated valid logs; ``import_xsens`` and
``import_mpu6050`` on mutated short copies of the measured files) and ``graph-calib import``.  Examples are
derandomized (the same every run) and small, so the file runs in well under a minute.
"""

import contextlib
import functools
import io as _io
import json
import math
import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
from _shared import REAL_DATA, make_experiment
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from graph_calib import importers, io
from graph_calib.cli import main
from graph_calib.errors import InputError
from graph_calib.records.experiment import Experiment, Result

#: Warnings a corrupted file may raise on its way to being refused (an empty table, overflow in a norm) or a
#: mutation on its way to corrupting it (complex cast to real).
pytestmark = [pytest.mark.filterwarnings("ignore:loadtxt. input contained no data:UserWarning"),
              pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning"),
              pytest.mark.filterwarnings("ignore::numpy.exceptions.ComplexWarning")]

SETTINGS = {"deadline": None, "derandomize": True, "database": None, "suppress_health_check": list(HealthCheck)}


def examples(n):
    return settings(max_examples=n, **SETTINGS)


def refused_or_read(read, *files, must_refuse=False):
    """``read()``; an InputError must be one line naming one of ``files``; any other exception propagates."""
    try:
        out = read()
    except InputError as exc:
        msg = str(exc)
        assert msg.strip(), "an empty message"
        assert "\n" not in msg, f"a message on more than one line: {msg!r}"
        assert any(Path(f).name in msg for f in files), f"the message names no file: {msg!r}"
        return exc
    assert not must_refuse, "a broken file was accepted"
    return out


@contextlib.contextmanager
def scratch():
    with tempfile.TemporaryDirectory(prefix="gc-prop-") as d:
        yield Path(d)


# ---------------------------------------------------------------------------
# text mutations (CSV, xsens, mpu6050 logs, JSON, TOML)
# ---------------------------------------------------------------------------

#: Cells that look nearly like numbers: what a broken logger or a hand edit leaves.
ODD_CELLS = ["", "nan", "NaN", "inf", "-inf", "1e999", "-", "+-1", "0x10", "1_0", "1,5", "\u0663", "\u00b2", "1e",
             ".", "--5", " ", '"', '"1"', "#", "1#2", "\x00", "\x0c", "\u00a0", "9" * 400, "1e-400", "true"]


@st.composite
def text_mutation(draw):
    """A function ``bytes -> bytes``: lines cut, bytes inserted or overwritten, a cut mid-line, cells or
    columns swapped, lines duplicated or swapped, a cell replaced."""
    kind = draw(st.sampled_from(["cut_lines", "truncate", "insert_bytes", "overwrite_bytes", "swap_columns",
                                 "swap_lines", "duplicate_line", "odd_cell", "replace_line"]))
    u = draw(st.floats(0.0, 1.0))
    v = draw(st.floats(0.0, 1.0))
    blob = draw(st.binary(min_size=1, max_size=8))
    cell = draw(st.sampled_from(ODD_CELLS) | st.text(max_size=6))
    line_text = draw(st.text(max_size=30))

    def at(x, n):
        return min(int(x * n), max(n - 1, 0))

    def apply(data):
        if kind in ("truncate", "insert_bytes", "overwrite_bytes"):
            k = at(u, len(data) + 1)
            if kind == "truncate":
                return data[:k]
            if kind == "insert_bytes":
                return data[:k] + blob + data[k:]
            return data[:k] + blob + data[k + len(blob):]
        lines = data.split(b"\n")
        n = len(lines)
        i, j = sorted((at(u, n), at(v, n)))
        if kind == "cut_lines":
            del lines[i:j + 1]
        elif kind == "swap_lines":
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "duplicate_line":
            lines.insert(i, lines[i])
        elif kind == "replace_line":
            lines[i] = line_text.encode("utf-8", "surrogatepass")
        else:
            sep = b"," if b"," in lines[i] else None
            cells = lines[i].split(sep) if sep else lines[i].split()
            if cells:
                a, b = at(u, len(cells)), at(v, len(cells))
                if kind == "swap_columns":      # the same two columns swapped in every line from i on
                    for r in range(i, n):
                        cs = lines[r].split(sep) if sep else lines[r].split()
                        if len(cs) > max(a, b):
                            cs[a], cs[b] = cs[b], cs[a]
                            lines[r] = (sep or b"  ").join(cs)
                else:
                    cells[a] = cell.encode("utf-8", "surrogatepass")
                    lines[i] = (sep or b"  ").join(cells)
        return b"\n".join(lines)

    return Mutation(apply, f"{kind}(u={u:.3g}, v={v:.3g}, blob={blob!r}, cell={cell!r}, line={line_text!r})")


def mutated(data, mutations):
    for m in mutations:
        data = m(data)
    return data


mutations = st.lists(text_mutation(), min_size=1, max_size=3)


# ---------------------------------------------------------------------------
# experiment file (HDF5)
# ---------------------------------------------------------------------------

DATASETS = ["imu/t", "imu/dtheta", "imu/dv", "imu/temperature", "table/t", "table/q_nf", "table/valid"]
ATTRS = [("/", "format"), ("/", "version"), ("/", "latitude_rad"), ("/", "gravity_mps2"), ("/", "imu_id"),
         ("/", "description"), ("imu", "rate_hz"), ("imu", "temperature_map"), ("imu/temperature", "names"),
         ("table", "q_fb_nominal")]
OPTIONAL_ATTRS = {"description", "temperature_map", "q_fb_nominal"}


@functools.lru_cache(maxsize=1)
def experiment_bytes():
    """A valid experiment file (200 samples and a table), as bytes."""
    with scratch() as d:
        path = d / "exp.h5"
        io.write_experiment(make_experiment(n=200), path)
        return path.read_bytes()


class Mutation:
    """A named function (shown by hypothesis when a property fails)."""

    def __init__(self, fn, text):
        self.fn, self.text = fn, text

    def __call__(self, *args):
        return self.fn(*args)

    def __repr__(self):
        return self.text


attr_values = st.one_of(
    st.integers(-2**63, 2**63 - 1), st.floats(), st.text(max_size=12), st.binary(max_size=12), st.booleans(),
    hnp.arrays(st.sampled_from([np.float64, np.float32, np.int64, np.int8, np.bool_, np.complex128, "S3"]),
               hnp.array_shapes(min_dims=0, max_dims=2, max_side=7)),
)
dataset_values = hnp.arrays(
    st.sampled_from([np.float64, np.float32, np.float16, np.int32, np.uint8, np.bool_, np.complex64, "S2"]),
    hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=8))


@st.composite
def h5_mutation(draw):
    """``(function of an open h5py.File, must the reader refuse?)``."""
    kind = draw(st.sampled_from(["del_dataset", "del_attr", "set_attr", "set_dataset", "bad_value", "retype",
                                 "reshape", "t_not_increasing", "bad_quaternion", "group_for_dataset",
                                 "dataset_for_group"]))
    ds = draw(st.sampled_from(DATASETS))
    where, attr = draw(st.sampled_from(ATTRS))
    value = draw(attr_values)
    array = draw(dataset_values)
    u = draw(st.floats(0.0, 1.0))
    bad = draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    dtype = draw(st.sampled_from([np.int64, np.int8, np.bool_, np.complex128, "S8", np.float32]))

    def replace(f, name, data):
        del f[name]
        f.create_dataset(name, data=data)

    def apply(f):
        if kind == "del_dataset":
            del f[ds]
        elif kind == "del_attr":
            del f[where].attrs[attr]
        elif kind == "set_attr":
            f[where].attrs[attr] = value
        elif kind == "set_dataset":
            replace(f, ds, array)
        elif kind == "bad_value":
            a = f[ds][()]
            if a.dtype.kind == "f":
                flat = a.reshape(-1)
                flat[min(int(u * flat.size), flat.size - 1)] = bad
                replace(f, ds, flat.reshape(a.shape))
            else:
                replace(f, ds, a.astype(np.int8))
        elif kind == "retype":
            a = f[ds][()]
            replace(f, ds, a.astype(dtype))
        elif kind == "reshape":
            a = f[ds][()]
            replace(f, ds, a.T if a.ndim == 2 else a[:, None])
        elif kind == "t_not_increasing":
            name = "imu/t" if u < 0.5 else "table/t"
            t = f[name][()]
            k = 1 + int(u * (t.size - 2))
            t[k] = t[k - 1] - (u < 0.25) * 1e-3
            replace(f, name, t)
        elif kind == "bad_quaternion":
            q = f["table/q_nf"][()]
            q[int(u * (q.shape[0] - 1))] *= 1.0 + 1e-3 + u
            replace(f, "table/q_nf", q)
        elif kind == "group_for_dataset":
            del f[ds]
            f.create_group(ds)
        else:
            name = "imu" if u < 0.5 else "table"
            del f[name]
            f.create_dataset(name, data=np.zeros(3))

    must = kind in ("del_dataset", "t_not_increasing", "bad_quaternion", "group_for_dataset", "dataset_for_group") \
        or (kind == "del_attr" and attr not in OPTIONAL_ATTRS) \
        or (kind == "bad_value") or (kind == "reshape")
    if kind == "retype":     # float32 is upcast; bool stays bool for /table/valid
        must = not ((dtype is np.float32 and ds != "table/valid") or (dtype is np.bool_ and ds == "table/valid"))
    text = {"del_dataset": f"del {ds}", "del_attr": f"del {where}.attrs[{attr}]",
            "set_attr": f"{where}.attrs[{attr}] = {value!r}", "set_dataset": f"{ds} = {array!r}",
            "bad_value": f"{ds}[{u:.3g}] = {bad}", "retype": f"{ds}.astype({dtype})", "reshape": f"{ds} reshaped",
            "t_not_increasing": f"t not increasing (u={u:.3g})", "bad_quaternion": f"q_nf scaled (u={u:.3g})",
            "group_for_dataset": f"{ds} a group", "dataset_for_group": f"imu/table a dataset (u={u:.3g})"}[kind]
    return Mutation(apply, text), must


def _set_attr(where, name, value):
    def apply(f):
        f[where].attrs[name] = value
    return Mutation(apply, f"{where}.attrs[{name}] = {value!r}"), False


@examples(150)
@given(muts=st.lists(h5_mutation(), min_size=1, max_size=3))
@example(muts=[_set_attr("/", "version", np.full(4, 1e8j))])     # found: numpy's repr of an array on two lines
@pytest.mark.slow
def test_read_experiment_refuses_mutated_files_with_one_line(muts):
    with scratch() as d:
        path = d / "exp.h5"
        path.write_bytes(experiment_bytes())
        applied = []
        with h5py.File(path, "r+") as f:
            for apply, m in muts:
                try:
                    apply(f)
                except (KeyError, TypeError, ValueError, IndexError):
                    continue      # the mutation does not apply after an earlier one (the object is gone)
                applied.append(m)
        must = applied == [True]  # several mutations may undo one another
        out = refused_or_read(lambda: io.read_experiment(path), path, must_refuse=must)
        if isinstance(out, Experiment):
            io.validate_experiment(out, path=path)


@examples(60)
@given(hits=st.lists(st.tuples(st.floats(0.0, 1.0), st.binary(min_size=1, max_size=16)), min_size=1, max_size=4))
@example(hits=[(0.05078125, b"\x01")])     # found: h5py's RuntimeError on a damaged B-tree
def test_read_experiment_refuses_overwritten_bytes(hits):
    data = bytearray(experiment_bytes())
    for u, blob in hits:
        k = min(int(u * len(data)), len(data) - len(blob))
        data[k:k + len(blob)] = blob
    with scratch() as d:
        path = d / "exp.h5"
        path.write_bytes(bytes(data))
        refused_or_read(lambda: io.read_experiment(path), path)


@examples(30)
@given(cut=st.floats(0.0, 0.999))
def test_read_experiment_refuses_a_truncated_file(cut):
    data = experiment_bytes()
    with scratch() as d:
        path = d / "exp.h5"
        path.write_bytes(data[:int(cut * len(data))])
        refused_or_read(lambda: io.read_experiment(path), path, must_refuse=True)


# ---------------------------------------------------------------------------
# result file (JSON)
# ---------------------------------------------------------------------------


def _result():
    rng = np.random.default_rng(3)
    names = ("gyro.bias.x", "gyro.bias.y", "gyro.bias.z", "accel.misalignment.zy", "time_lag.table")
    sig = rng.uniform(0.1, 1.0, 5) * np.array([1e-9, 1e-9, 1e-9, 1e-5, 1e-3])
    a = rng.normal(size=(5, 5)) * sig
    cov = a.T @ a
    return Result(
        source="sub1_20_30.h5", solver="sqrt-kf", t_ref_degC=25.0, temperature_range_degC=(20.1, 29.8),
        effects=("gyro.bias", "accel.misalignment", "time_lag.table"),
        values=dict(zip(names, [1.2e-8, 0.3, -3.3e-9, 5e-6, 0.004])), sigmas=dict(zip(names, sig.tolist())),
        covariance_names=names, covariance=0.5 * (cov + cov.T), residuals={"iterations": 7, "per_axis": [0.1, 0.2]},
        extra={"priors": {"gyro.bias": 1e-6}},
    )


RESULT_DOC = io.result_to_dict(_result())
KNOWN_NAMES = ["gyro.bias.x", "gyro.bias", "accel.scale.y", "time_lag.table", "truth", "sqrt-kf", "value", "sigma",
               "names", "matrix", "format", "version", "estimates", "covariance"]

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8) | st.sampled_from(KNOWN_NAMES),
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.sampled_from(KNOWN_NAMES) | st.text(max_size=6), inner, max_size=3),
    max_leaves=8)


def _paths(node, prefix=()):
    """Every path (tuple of keys and indices) into a JSON document, the root included."""
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, prefix + (i,))
    return out


RESULT_PATHS = _paths(RESULT_DOC)


@st.composite
def json_document(draw, doc, paths):
    """``doc`` (deep-copied) with 1 to 3 nodes replaced, deleted or given a further key."""
    doc = json.loads(json.dumps(doc))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(paths))
        op = draw(st.sampled_from(["replace", "delete", "add"]))
        value = draw(json_values)
        parent = doc
        try:
            for key in path[:-1]:
                parent = parent[key]
            if not path:
                doc = value
            elif op == "replace":
                parent[path[-1]] = value
            elif op == "delete":
                del parent[path[-1]]
            elif isinstance(parent[path[-1]], dict):
                parent[path[-1]][draw(st.sampled_from(KNOWN_NAMES) | st.text(max_size=5))] = value
            elif isinstance(parent[path[-1]], list):
                parent[path[-1]].append(value)
        except (KeyError, IndexError, TypeError):
            pass                 # an earlier edit removed the path
    return doc


@examples(200)
@given(doc=json_document(RESULT_DOC, RESULT_PATHS))
@example(doc={**RESULT_DOC, "t_ref_degC": 10**400})       # integers beyond the float range (by reading)
@example(doc={**RESULT_DOC, "estimates": {**RESULT_DOC["estimates"], "gyro.bias.x": {"value": 10**400, "sigma": 1}}})
def test_read_result_refuses_mutated_documents(doc):
    with scratch() as d:
        path = d / "sqrt-kf.json"
        path.write_text(json.dumps(doc), encoding="utf-8")
        out = refused_or_read(lambda: io.read_result(path), path)
        if isinstance(out, Result):
            io.validate_result(out, path=path)


@examples(100)
@given(muts=mutations)
def test_read_result_refuses_mutated_text(muts):
    with scratch() as d:
        path = d / "sqrt-kf.json"
        path.write_bytes(mutated(json.dumps(RESULT_DOC, indent=1).encode(), muts))
        refused_or_read(lambda: io.read_result(path), path)


# ---------------------------------------------------------------------------
# campaign manifest (TOML)
# ---------------------------------------------------------------------------

MANIFEST_SLOTS = {
    "id": '"BINS-RT 0001"', "grade": '"navigation"', "file": '"a.h5"', "tref": "25", "name": '"second"',
    "prior": "1e-6", "effects": '["gyro.bias_tc2"]', "exclude": '["lever_arm"]', "keyframe": "0.5",
    "solvers": '"both"', "maxit": "20",
}
MANIFEST = """\
[imu]
id = {id}
grade = {grade}

[[experiment]]
file = {file}
t_ref_degC = {tref}

[[experiment]]
file = "b.h5"
name = {name}

[priors]
"gyro.bias" = {prior}
accel.bias_tc = 2e-4

[model]
effects = {effects}
exclude = {exclude}

[solver]
keyframe_s = {keyframe}
solvers = {solvers}
max_iterations = {maxit}
"""


def _toml_string(s):
    return json.dumps(s)


toml_scalars = st.one_of(
    st.integers().map(str), st.floats().map(lambda x: "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
                                            if math.isinf(x) else repr(x)),
    st.booleans().map(lambda b: str(b).lower()), st.text(max_size=10).map(_toml_string),
    st.sampled_from(['"consumer"', '"tactical"', '"sqrt-kf"', '"gyro.bias"', '"a.h5"', '"../a.h5"', '"/"', '""',
                     '"b.h5"', "1979-05-27", "07:32:00", '"\\u0000"', "0x10", "1_000", "+inf"]),
)
toml_values = st.recursive(toml_scalars, lambda inner: st.lists(inner, max_size=3).map(
    lambda xs: "[" + ", ".join(xs) + "]") | st.dictionaries(st.sampled_from(["a", "file", "id", "x.y"]), inner,
                                                             max_size=2).map(
    lambda d: "{" + ", ".join(f"{k} = {v}" for k, v in d.items()) + "}"), max_leaves=5)


@examples(150)
@given(slots=st.dictionaries(st.sampled_from(sorted(MANIFEST_SLOTS)), toml_values | st.text(max_size=12),
                             min_size=1, max_size=3),
       extra=st.lists(st.text(max_size=20), max_size=2))
@example(slots={"grade": "[]"}, extra=[])                  # found: an unhashable grade
@example(slots={"tref": "1" + "0" * 400}, extra=[])       # integers beyond the float range (by reading)
@example(slots={"keyframe": "1" + "0" * 400}, extra=[])
@example(slots={"prior": "1" + "0" * 400}, extra=[])
def test_read_manifest_refuses_mutated_values(slots, extra):
    text = MANIFEST.format(**{**MANIFEST_SLOTS, **slots}) + "\n".join(extra)
    with scratch() as d:
        (d / "a.h5").write_bytes(b"")
        (d / "b.h5").write_bytes(b"")
        path = d / "campaign.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        refused_or_read(lambda: io.read_manifest(path), path)


@examples(100)
@given(muts=mutations)
def test_read_manifest_refuses_mutated_text(muts):
    with scratch() as d:
        (d / "a.h5").write_bytes(b"")
        (d / "b.h5").write_bytes(b"")
        path = d / "campaign.toml"
        path.write_bytes(mutated(MANIFEST.format(**MANIFEST_SLOTS).encode(), muts))
        refused_or_read(lambda: io.read_manifest(path), path)


# ---------------------------------------------------------------------------
# importers
# ---------------------------------------------------------------------------


def _valid_csv(n=150):
    e = make_experiment(n=n, with_table=False)
    dt = e.dt[:, None]
    table = np.column_stack([e.t, e.dtheta / dt, e.dv / dt, e.temperature[:, 0]])
    lines = ["time,gx,gy,gz,ax,ay,az,temp"] + [",".join(repr(float(v)) for v in row) for row in table]
    return ("\n".join(lines) + "\n").encode()


CSV_BYTES = _valid_csv()
CSV_COLUMNS = {"t": 0, "gx": 1, "gy": 2, "gz": 3, "ax": 4, "ay": 5, "az": 6, "temp": 7}
CSV_OPTIONS = {"columns": CSV_COLUMNS, "latitude_rad": 0.95, "gravity_mps2": 9.80, "header_lines": 1}


def test_the_unmutated_inputs_import():
    with scratch() as d:
        (d / "log.csv").write_bytes(CSV_BYTES)
        assert importers.import_csv(d / "log.csv", **CSV_OPTIONS).n_samples == 150
        acc, gyro, mpu = _real_copies(d)
        assert importers.import_xsens(acc, gyro).n_samples == 300
        assert importers.import_mpu6050(mpu).n_samples == 300


def _insert(blob):
    return Mutation(lambda data: blob + data, f"insert_bytes(at 0, {blob!r})")


@examples(150)
@given(muts=mutations)
@example(muts=[_insert(b"\x80")])      # found on the merged csv reader: UnicodeDecodeError while scanning rows
def test_import_csv_refuses_mutated_logs(muts):
    with scratch() as d:
        path = d / "log.csv"
        path.write_bytes(mutated(CSV_BYTES, muts))
        refused_or_read(lambda: importers.import_csv(path, **CSV_OPTIONS), path)


cell_text = st.one_of(st.floats(allow_nan=False).map(repr), st.integers(-40000, 70000).map(str),
                      st.sampled_from(ODD_CELLS), st.text(max_size=4))
column_value = st.one_of(st.integers(-2, 9), st.text(max_size=4), st.sampled_from(["gx", "time", "a", "0", "-1"]))
column_key = st.sampled_from(["t", "gx", "gy", "gz", "ax", "ay", "az", "temp", "temp:case", "temp:", "x"])


@examples(150)
@given(rows=st.lists(st.lists(cell_text, min_size=1, max_size=9), max_size=25),
       header=st.lists(st.text(max_size=20), max_size=2),
       delimiter=st.sampled_from([",", ";", "\t", None, " ", "", "ab", '"', "#", "\n", "\r", "."]),
       columns=st.fixed_dictionaries({k: st.integers(0, 8) for k in ("gx", "gy", "gz", "ax", "ay", "az")})
       | st.dictionaries(column_key, column_value, max_size=9),
       options=st.fixed_dictionaries({}, optional={
           "rate_hz": st.none() | st.floats(), "time_units": st.sampled_from(["s", "ms", "h"]),
           "gyro_units": st.sampled_from(["rad/s", "deg", "rpm"]), "accel_units": st.sampled_from(["g", "m/s", "x"]),
           "gyro_counts_per_unit": st.none() | st.floats(), "accel_counts_per_unit": st.none() | st.floats(),
           "temperature_degC": st.none() | st.floats(), "header_lines": st.integers(-1, 3),
           "temperature_map": st.none() | st.lists(st.integers(-1, 3), max_size=7),
           "latitude_rad": st.floats(), "gravity_mps2": st.floats()}))
@example(rows=[["1", "2", "3", "4", "5", "6"]], header=[], delimiter="ab", columns=CSV_COLUMNS, options={})
@example(rows=[["1", "2", "3", "4", "5", "6"]], header=[], delimiter="", columns=CSV_COLUMNS, options={})  # found
def test_import_csv_refuses_random_text_and_columns(rows, header, delimiter, columns, options):
    sep = delimiter if delimiter else ","
    text = "\n".join(header + [sep.join(r) for r in rows])
    with scratch() as d:
        path = d / "log.csv"
        path.write_bytes(text.encode("utf-8", "surrogatepass"))
        kw = {"latitude_rad": 0.95, "gravity_mps2": 9.80, "rate_hz": 100.0, "temperature_degC": 20.0,
              "delimiter": delimiter, "header_lines": len(header)}
        kw.update(options)
        try:
            importers.import_csv(path, columns=columns, **kw)
        except InputError as exc:
            msg = str(exc)
            assert msg.strip() and "\n" not in msg, msg        # an option's error names the option, not the file


def _real_copies(d, n=300):
    """Short copies of the measured files in ``d``: (xsens acc, xsens gyro, mpu6050)."""
    out = []
    for src in (REAL_DATA / "imu_tk_xsens" / "xsens_acc.mat", REAL_DATA / "imu_tk_xsens" / "xsens_gyro.mat"):
        dst = d / src.name
        dst.write_bytes(b"\n".join(src.read_bytes().split(b"\n")[:n]) + b"\n")
        out.append(dst)
    src = REAL_DATA / "mpu6050_uncuyo" / "example_data_calibration.csv"
    dst = d / src.name
    dst.write_bytes(b"\n".join(src.read_bytes().split(b"\n")[:n + 5]) + b"\n")
    out.append(dst)
    return out


@examples(100)
@given(muts=mutations, which=st.sampled_from(["acc", "gyro", "both"]))
def test_import_xsens_refuses_mutated_copies(muts, which):
    with scratch() as d:
        acc, gyro, _ = _real_copies(d)
        for p in {"acc": [acc], "gyro": [gyro], "both": [acc, gyro]}[which]:
            p.write_bytes(mutated(p.read_bytes(), muts))
        refused_or_read(lambda: importers.import_xsens(acc, gyro), acc, gyro)


@examples(100)
@given(muts=mutations)
def test_import_mpu6050_refuses_mutated_copies(muts):
    with scratch() as d:
        _, _, mpu = _real_copies(d)
        mpu.write_bytes(mutated(mpu.read_bytes(), muts))
        refused_or_read(lambda: importers.import_mpu6050(mpu), mpu)


# ---------------------------------------------------------------------------
# graph-calib import: exit 0 or 2, nothing half written
# ---------------------------------------------------------------------------

OPTION_VALUES = {
    "--latitude-deg": st.sampled_from(["45", "-91", "nan", "x", "1e9"]),
    "--gravity": st.sampled_from(["9.81", "1.0", "nan", "-3"]),
    "--temperature": st.sampled_from(["20", "400", "nan", "-inf"]),
    "--rate-hz": st.sampled_from(["100", "0", "-5", "nan", "1e300", "1e-300"]),
    "--accel-scale": st.sampled_from(["415", "0", "nan", "-1"]),
    "--gyro-scale": st.sampled_from(["4770", "0", "inf"]),
    "--offset": st.sampled_from(["32768", "nan", "1e20"]),
    "--columns": st.sampled_from(["t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6,temp=7", "gx=1", "t=0,gx=\u00b2", "t=--5",
                                  "t=0,,gx=1", "time=0,gx=gx,gy=gy,gz=gz,ax=ax,ay=ay,az=az,temp=temp", "=1", "t"]),
    "--delimiter": st.sampled_from(["comma", "tab", "ab", "", '"', "#", ";", "whitespace"]),
    "--header-lines": st.sampled_from(["0", "1", "-1", "99"]),
    "--temperature-map": st.sampled_from(["0,0,0,0,0,0", "1,2", "0,0,0,0,0,9", "a,b,c,d,e,f"]),
    "--gyro-units": st.sampled_from(["rad/s", "deg", "rpm"]),
    "--time-units": st.sampled_from(["s", "ms", "h"]),
}


@examples(80)
@given(fmt=st.sampled_from(["csv", "xsens", "mpu6050"]), muts=st.lists(text_mutation(), max_size=2),
       options=st.dictionaries(st.sampled_from(sorted(OPTION_VALUES)), st.just(None), max_size=3).flatmap(
           lambda d: st.fixed_dictionaries({k: OPTION_VALUES[k] for k in d})),
       base=st.booleans())
@example(fmt="csv", muts=[], options={"--columns": "t=0,gx=\u00b2"}, base=True)    # found: int("²") in --columns
@example(fmt="csv", muts=[], options={"--delimiter": "ab"}, base=True)           # found: loadtxt's TypeError
def test_import_command_exits_0_or_2_and_never_leaves_a_partial_file(fmt, muts, options, base):
    with scratch() as d:
        acc, gyro, mpu = _real_copies(d)
        csv = d / "log.csv"
        csv.write_bytes(CSV_BYTES)
        inputs = {"csv": [csv], "xsens": [acc, gyro], "mpu6050": [mpu]}[fmt]
        for p in inputs:
            p.write_bytes(mutated(p.read_bytes(), muts))
        out_dir = d / "out"
        out_dir.mkdir()
        out = out_dir / "exp.h5"
        argv = ["import", fmt, *map(str, inputs), "--out", str(out)]
        if fmt == "csv" and base:
            argv += ["--columns", "t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6,temp=7", "--header-lines", "1",
                     "--latitude-deg", "54", "--gravity", "9.80"]
        for k, v in options.items():
            argv += [k, v] if not v.startswith("-") else [f"{k}={v}"]
        err = _io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(_io.StringIO()):
            try:
                code = main(argv)
            except SystemExit as exc:      # argparse: a bad option value
                code = exc.code
        assert code in (0, 2), f"exit {code}: {err.getvalue()}"
        if code == 0:
            io.read_experiment(out)        # what import writes, the reader reads
        else:
            assert len(err.getvalue().strip().splitlines()) == 1, err.getvalue()
            assert "Traceback" not in err.getvalue()
            assert not out.exists()
        assert [p.name for p in out_dir.iterdir()] in ([], ["exp.h5"])      # no temporary file left
