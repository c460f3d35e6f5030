r"""The result file (JSON): :func:`read_result`, :func:`write_result`, :func:`validate_result`, :func:`result_to_dict`.

The reader checks every rule of the format (``docs/data-format.md``) and refuses
a file that breaks one with a single :class:`~graph_calib.errors.InputError`
naming the file and the key.  The writer runs the same checks before writing,
writes floats with ``repr`` (they read back bit for bit), and writes atomically.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from graph_calib.sensors import effects, params
from graph_calib.errors import InputError
from graph_calib.records.experiment import Result
from graph_calib.io.atomic import atomic_write_text, dumps_json
from graph_calib.io.checks import _first, _is_int, _is_real, _show, version_problem

RESULT_FORMAT = "imu-calibration-result"
RESULT_VERSION = 1

#: Relative asymmetry accepted in a result covariance, ``|P - P.T| <= tol * sqrt(d_i d_j)``.
COVARIANCE_SYMMETRY_TOL = 1e-6

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
    """Check a :class:`~graph_calib.records.experiment.Result` against the result file format.

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
        if not isinstance(name, str) or name not in effects.EFFECTS:
            raise InputError(f"unknown parameter {_show(name)}; known: {', '.join(effects.EFFECTS)}",
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
    if "temperature_curves" in r.extra:
        validate_temperature_curves(r.extra["temperature_curves"], path=path)


def validate_temperature_curves(curves, *, path):
    """Check a truth file's ``temperature_curves`` (data-format.md).

    ``{flat element: {"t0_degC": t0, "coefficients": [c0, c1, ...]}}``: each key a known flat element
    of a temperature-dependent parameter (one with temperature coefficients in the catalogue, e.g.
    ``accel.bias.y``), ``t0_degC`` a finite number, ``coefficients`` a non-empty list of finite numbers
    (SI; value(T) = sum_i c_i (T - t0)^i) and no other key.

    Raises
    ------
    InputError
        Naming the file and the offending entry.
    """
    ds0 = "temperature_curves"
    if not isinstance(curves, dict):
        raise InputError(f"must be an object {{element: {{t0_degC, coefficients}}}}, got {_show(curves)}",
                         path=path, dataset=ds0)
    for name, entry in curves.items():
        ds = f'{ds0}["{name}"]'
        _check_element_name(name, path=path, dataset=ds)
        parameter = params.split_element_name(name)[0]
        if effects.EFFECTS[parameter].temperature_of is not None or not effects.temperature_family(parameter)[1]:
            raise InputError(f"{_show(name)} is not an element of a temperature-dependent parameter (a curve over "
                             "temperature is given for bias and scale elements)", path=path, dataset=ds)
        if not isinstance(entry, dict) or set(entry) != {"t0_degC", "coefficients"}:
            raise InputError("must be an object with exactly 't0_degC' and 'coefficients'", path=path, dataset=ds)
        _check_finite_real(entry["t0_degC"], path=path, dataset=ds + ".t0_degC")
        coef = entry["coefficients"]
        if not isinstance(coef, list) or not coef:
            raise InputError(f"must be a non-empty list of numbers [c0, c1, ...], got {_show(coef)}", path=path,
                             dataset=ds + ".coefficients")
        for i, v in enumerate(coef):
            _check_finite_real(v, path=path, dataset=f"{ds}.coefficients[{i}]", what="coefficient")


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
    problem = version_problem(doc["version"], RESULT_VERSION)
    if problem:
        raise InputError(problem, path=path, dataset="version")
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
