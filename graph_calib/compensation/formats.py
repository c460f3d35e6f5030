r"""The compensation table's files: JSON, CSV and a C header (``docs/compensation.md`` shows each).

``json``
    :meth:`graph_calib.compensation.table.CompensationTable.to_dict`, numbers
    written with ``repr`` (they read back bit for bit).
``csv``
    ``# key = JSON value`` header lines (format, version, provenance, the
    interpolation rule, and one ``# element <name> = {...}`` line per element with
    its unit, sensor, kind and checks), then one row per grid temperature:
    ``temperature_degC`` and, for every element, ``<element>`` and
    ``<element>_sigma``.  Constant elements are columns too, the same number in
    every row, so that a loader needs nothing but the rows.  Numbers with ``repr``.
``c-header``
    Plain ``static const double`` arrays (the grid, each element's values and
    sigmas) and scalars (the constants), units and sensors in comments, the
    interpolation rule and the sensor equations in the leading comment; numbers
    with ``repr`` (17 significant digits at most, exact).  Written for an INS; not
    read back by graph-calib.

:func:`read_table` reads the JSON and CSV files (the format is told by the content).
Every file is written atomically (:mod:`graph_calib.io.atomic`).
"""

from __future__ import annotations

import csv
import io as _io
import json
import re
from pathlib import Path

import numpy as np

from graph_calib import __version__, io
from graph_calib.compensation.elements import BENCH_PARAMETERS, sensor_name, unit_of
from graph_calib.compensation.table import (
    INTERPOLATION, TABLE_FORMAT, TABLE_VERSION, CompensationTable, check_header,
)
from graph_calib.sensors.effects import EFFECTS
from graph_calib.errors import InputError
from graph_calib.sensors.params import split_element_name

#: Table file formats :func:`write_table` writes.
TABLE_FORMATS = ("json", "csv", "c-header")
#: Suffix of each format's file.
SUFFIX = {"json": ".json", "csv": ".csv", "c-header": ".h"}


def _num(v):
    """A float as text that reads back exactly (Python's shortest round-trip ``repr``)."""
    return repr(float(v))


# ---------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------


def table_json(table):
    """The JSON text of a table."""
    doc = table.to_dict()
    doc["written_by"] = f"graph-calib {__version__}"
    return io.dumps_json(doc)


def table_csv(table):
    """The CSV text of a table (module docstring)."""
    doc = table.to_dict()
    lines = []
    for key, value in doc.items():
        if key in ("grid_degC", "elements", "constants"):
            continue
        lines.append(f"# {key} = {json.dumps(io.to_json_builtin(value))}")
    lines.append(f"# written_by = {json.dumps(f'graph-calib {__version__}')}")
    for kind, section in (("temperature", doc["elements"]), ("constant", doc["constants"])):
        for name, entry in section.items():
            meta = {"kind": kind, "unit": entry["unit"], "sensor": entry["sensor"]}
            meta.update({k: v for k, v in entry.items() if k in ("calibrated_range_degC", "interpolation_error")})
            lines.append(f"# element {name} = {json.dumps(io.to_json_builtin(meta))}")
    columns = ["temperature_degC"]
    data = [table.grid_degC]
    g = table.grid_degC.size
    for name in table.elements():
        columns += [name, f"{name}_sigma"]
        if name in table.curves:
            data += [table.curves[name].values, table.curves[name].sigmas]
        else:
            v, s = table.constants[name]
            data += [np.full(g, v), np.full(g, s)]
    lines.append(",".join(columns))
    for k in range(g):
        lines.append(",".join(_num(col[k]) for col in data))
    return "\n".join(lines) + "\n"


def _ident(name):
    return "gc_" + re.sub(r"[^0-9A-Za-z]", "_", name)


def _equations(table):
    """The sensor equations of the declared terms the table holds, for the C header's comment."""
    params = set(table.layout.names)
    further = sorted(p for p in params if not EFFECTS[p].declared)
    lines = [
        "Sensor model (docs/model.md), per triad, every element at its own sensor's temperature:",
        "  measured = true + b + diag(s) true + M true [+ further terms]",
        "  b: *_bias (one per axis); s: *_scale (one per axis); M: *_misalignment, element 'ij' = M[i][j]",
        "  (row i = the sensor axis, column j = the true-signal component; zero diagonal).",
        "With only these terms (linear in the signal) the correction is exact in one step:",
        "  true = (I + diag(s) + M)^-1 (measured - b),  measured = dtheta/dt (rad/s) or dv/dt (m/s^2).",
    ]
    if further:
        lines.append("Further terms held here (see docs/model.md and graph_calib/sensors/sensor_model.py): "
                     + ", ".join(f"{p} ({EFFECTS[p].term})" for p in further) + ".")
    return lines


def table_c_header(table, *, guard="GRAPH_CALIB_COMPENSATION_TABLE_H"):
    """The C header text of a table (module docstring)."""
    info = table.info
    g = table.grid_degC.size
    out = ["/*", f" * IMU compensation table ({TABLE_FORMAT} version {TABLE_VERSION}), written by "
                 f"graph-calib {__version__}.",
           f" * IMU {info.get('imu_id') or '?'}; solver {info.get('solver', '?')}; stitched model "
           f"{info.get('stitch_model', '?')}; from {info.get('source') or '?'}.",
           " * Units SI (rad/s, rad, m/s^2, 1), temperatures degC.", " *",
           f" * Interpolation: {INTERPOLATION}:",
           " *   j with grid[j] <= T <= grid[j+1], w = (T - grid[j]) / (grid[j+1] - grid[j]),",
           " *   p(T) = (1 - w) p[j] + w p[j+1];  T < grid[0]: p[0];  T > grid[N-1]: p[N-1].",
           " * Sensors: gyro.x/y/z and accel.x/y/z, each read from its channel of the record's temperature_map.",
           " *"]
    out += [f" * {line}" for line in _equations(table)]
    if info.get("calibrated_range_degC"):
        lo, hi = info["calibrated_range_degC"]
        out.append(f" * Calibrated sensor temperatures {lo:.2f} .. {hi:.2f} degC; the grid reaches at most one "
                   "step beyond.")
    out.append(f" * Not in the table (bench set-up, not IMU corrections): {', '.join(BENCH_PARAMETERS)}.")
    out += [" */", f"#ifndef {guard}", f"#define {guard}", "",
            f"#define GC_TABLE_VERSION {TABLE_VERSION}", f"#define GC_N_GRID {g}", "",
            "/* grid temperatures, degC */",
            f"static const double gc_grid_degC[GC_N_GRID] = {{{', '.join(_num(t) for t in table.grid_degC)}}};", ""]
    for name, c in table.curves.items():
        err = c.interpolation_error
        note = (f"; interpolation error up to {err['max_abs']:.3g} ({err['max_in_sigma']:.2g} sigma)"
                if err.get("max_abs") is not None else "")
        out.append(f"/* {name}: {unit_of(name)}, at the {sensor_name(name)} temperature{note} */")
        out.append(f"static const double {_ident(name)}[GC_N_GRID] = {{{', '.join(_num(v) for v in c.values)}}};")
        out.append(f"static const double {_ident(name)}_sigma[GC_N_GRID] = "
                   f"{{{', '.join(_num(v) for v in c.sigmas)}}};")
    if table.constants:
        out += ["", "/* constant elements (no temperature dependence) */"]
    for name, (v, s) in table.constants.items():
        out.append(f"static const double {_ident(name)} = {_num(v)};  /* {unit_of(name)} */")
        out.append(f"static const double {_ident(name)}_sigma = {_num(s)};  /* {unit_of(name)}, one sigma */")
    out += ["", f"#endif /* {guard} */", ""]
    return "\n".join(out)


def write_table(table, path, *, fmt="json"):
    """Write a table atomically in ``fmt`` (:data:`TABLE_FORMATS`); returns the path."""
    if fmt not in TABLE_FORMATS:
        raise InputError(f"unknown table format {fmt!r}; known: {', '.join(TABLE_FORMATS)}", dataset="--format")
    path = Path(path)
    if fmt == "c-header":
        guard = "GC_" + re.sub(r"[^0-9A-Za-z]", "_", path.name).upper()
        text = table_c_header(table, guard=guard)
    else:
        text = table_json(table) if fmt == "json" else table_csv(table)
    io.atomic_write_text(path, text)
    return path


# ---------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------


def read_table(path):
    """Read a compensation table file (JSON or CSV, told by its content).

    Raises
    ------
    graph_calib.errors.InputError
        Naming the file and the key: missing, unreadable, not a table, a newer
        version, an unknown element, numbers that break the layout.
    """
    path = Path(path)
    text = _read_text(path)
    head = text.lstrip()[:1]
    if head == "{":
        try:
            doc = json.loads(text)
        except ValueError as exc:
            raise InputError(f"not valid JSON ({str(exc).splitlines()[0]})", path=path) from None
        return CompensationTable.from_dict(doc, path=path)
    if head == "#" and text.lstrip().startswith("# format"):
        return CompensationTable.from_dict(_csv_document(text, path), path=path)
    if text.lstrip().startswith("/*"):
        raise InputError("a C header table is written for an INS, not read back: use the JSON or CSV table",
                         path=path)
    raise InputError("not a compensation table (neither its JSON nor its CSV)", path=path)


def _read_text(path):
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path=path)
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", path=path) from None


_HEADER = re.compile(r"^#\s*(element\s+)?(\S+)\s*=\s*(.*)$")


def _csv_document(text, path):
    """The :meth:`CompensationTable.to_dict` document a CSV table holds."""
    doc, meta = {}, {}
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        if line.startswith("#"):
            m = _HEADER.match(line)
            if not m:
                raise InputError(f"line {lineno}: a header line is '# key = JSON value'", path=path)
            try:
                value = json.loads(m.group(3))
            except ValueError:
                raise InputError(f"line {lineno}: the value of {m.group(2)} is not JSON", path=path) from None
            (meta if m.group(1) else doc)[m.group(2)] = value
        else:
            rows.append((lineno, line))
    check_header(doc.get("format"), doc.get("version"), path=path)
    if not rows:
        raise InputError("no column header and no rows", path=path)
    reader = csv.reader(_io.StringIO("\n".join(line for _, line in rows)))
    table = list(reader)
    columns = table[0]
    if not columns or columns[0] != "temperature_degC":
        raise InputError(f"line {rows[0][0]}: the first column must be temperature_degC", path=path)
    expected = ["temperature_degC"] + [c for n in meta for c in (n, f"{n}_sigma")]
    if sorted(columns) != sorted(expected) or len(set(columns)) != len(columns):
        extra = sorted(set(columns) - set(expected))
        lacking = sorted(set(expected) - set(columns))
        raise InputError(f"line {rows[0][0]}: columns do not match the '# element' lines"
                         f"{' (no element line for ' + ', '.join(extra) + ')' if extra else ''}"
                         f"{' (missing ' + ', '.join(lacking) + ')' if lacking else ''}", path=path)
    data = []
    for (lineno, _), cells in zip(rows[1:], table[1:]):
        if len(cells) != len(columns):
            raise InputError(f"line {lineno}: {len(cells)} values for {len(columns)} columns", path=path)
        try:
            data.append([float(c) for c in cells])
        except ValueError:
            raise InputError(f"line {lineno}: not a number", path=path) from None
    a = np.array(data, dtype=float).reshape(len(data), len(columns))
    col = {c: a[:, i] for i, c in enumerate(columns)}
    doc["grid_degC"] = col["temperature_degC"].tolist()
    doc["elements"], doc["constants"] = {}, {}
    for name, m in meta.items():
        if not isinstance(m, dict) or m.get("kind") not in ("temperature", "constant"):
            raise InputError("kind must be 'temperature' or 'constant'", path=path, dataset=f"element {name}")
        entry = {k: v for k, v in m.items() if k != "kind"}
        v, s = col[name], col[f"{name}_sigma"]
        if m["kind"] == "temperature":
            entry.update(values=v.tolist(), sigmas=s.tolist())
            doc["elements"][name] = entry
        else:
            if v.size == 0 or np.any(v != v[0]) or np.any(s != s[0]):
                raise InputError("a constant element must hold the same value (and sigma) in every row", path=path,
                                 dataset=name)
            entry.update(value=float(v[0]), sigma=float(s[0]))
            doc["constants"][name] = entry
    return doc


def element_identifier(name):
    """The C identifier of an element in the header (``gyro.bias.x`` -> ``gc_gyro_bias_x``)."""
    split_element_name(name)
    return _ident(name)


__all__ = ["TABLE_FORMATS", "SUFFIX", "table_json", "table_csv", "table_c_header", "write_table", "read_table",
           "element_identifier"]
