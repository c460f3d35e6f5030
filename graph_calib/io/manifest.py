r"""The campaign manifest (TOML): :func:`read_manifest` giving a :class:`Campaign`.

The reader checks the layout of ``docs/data-format.md`` and refuses a manifest
that breaks a rule with a single :class:`~graph_calib.errors.InputError` naming
the manifest and the table or key.
"""

from __future__ import annotations

import contextlib
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the tomli backport, declared in pyproject.toml for it
    import tomli as tomllib

from graph_calib.sensors import effects, params
from graph_calib.errors import InputError
from graph_calib.io.checks import _is_int, _is_real, _show
import graph_calib.solvers.registry as registry



def _solver_choice_problem(value):
    """Why ``value`` is not a ``[solver] solvers`` value the registry accepts, or None."""
    try:
        registry.parse_choice(value, campaign=True)
    except ValueError as exc:
        return str(exc)
    return None


#: Options of the ``[solver]`` table: name -> (description, check returning an error text or None).
SOLVER_OPTIONS = {
    "solvers": ("which solvers run (graph_calib.solvers.registry.parse_choice): 'both' (the default solvers and "
                "every campaign solver), 'per-subrange' (the default solvers), or registered solver names joined "
                "by '+'", _solver_choice_problem),
    "keyframe_s": ("length of one keyframe (preintegration interval), s",
                   lambda v: None if _is_real(v) and math.isfinite(v) and v > 0 else "must be a positive number"),
    "max_iterations": ("largest number of solver iterations",
                       lambda v: None if _is_int(v) and v > 0 else "must be a positive integer"),
    "diagnose": ("the closed loop on every experiment of a campaign (graph-calib campaign): true (default) or false",
                 lambda v: None if isinstance(v, bool) else "must be true or false"),
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
        A key of :data:`graph_calib.sensors.params.GRADES`.
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
        """The :class:`~graph_calib.sensors.params.Layout` of the modelled parameters (a curve's order with the
        orders below it, as the calibration model holds them: :func:`~graph_calib.sensors.effects.with_lower_orders`)."""
        return params.Layout.declared(extra=effects.with_lower_orders(self.effects), exclude=self.exclude)

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
    if not isinstance(grade, str) or grade not in params.GRADES:
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
        if file is None or file == "":
            raise InputError("missing file", path=path, dataset=where)
        if not isinstance(file, str):
            raise InputError(f"must be the experiment file's path as a string, got {_show(file)}", path=path,
                             dataset=f"{where}.file")
        resolved = (path.parent / file).resolve()
        if not resolved.is_file():
            raise InputError(f"experiment file {resolved} " + ("is a folder" if resolved.is_dir() else "not found"),
                             path=path, dataset=f"{where}.file")
        t_ref = entry.get("t_ref_degC")
        if t_ref is not None:
            if not _is_real(t_ref) or not math.isfinite(t_ref):
                raise InputError(f"t_ref_degC must be a number, got {_show(t_ref)}", path=path,
                                 dataset=f"{where}.t_ref_degC")
            t_ref = float(t_ref)
        name = entry.get("name", Path(file).stem)
        if not isinstance(name, str) or not name:
            raise InputError(f"name must be a non-empty string, got {_show(name)}", path=path, dataset=f"{where}.name")
        if any(c in name for c in "/\\\0") or name.startswith("."):
            raise InputError(f"name {_show(name)} names the experiment's folder under the output: one folder name, "
                             "without a path separator and not starting with '.'", path=path, dataset=f"{where}.name")
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
        if name not in effects.EFFECTS:
            hint = ""
            with contextlib.suppress(KeyError):
                hint = f" (priors are per parameter: use {_show(params.split_element_name(name)[0])})"
            raise InputError(f"unknown parameter {_show(name)}{hint}; known: {', '.join(effects.EFFECTS)}",
                             path=path, dataset=where)
        if not _is_real(sigma) or not math.isfinite(sigma) or sigma <= 0:
            raise InputError(f"prior sigma must be a positive number (SI), got {_show(sigma)}", path=path, dataset=where)
        priors[name] = float(sigma)

    model = doc.get("model", {})
    if not isinstance(model, dict):
        raise InputError("must be a table", path=path, dataset="[model]")
    _unknown_keys(model, _MODEL_KEYS, path=path, where="[model]")
    further = _name_list(model.get("effects", []), path=path, where="[model].effects")
    for name in further:
        if name in effects.DECLARED:
            raise InputError(f"{_show(name)} is already in the declared model", path=path, dataset="[model].effects")
        if name not in effects.FURTHER_EFFECTS:
            raise InputError(f"unknown effect {_show(name)}; known: {', '.join(effects.FURTHER_EFFECTS)}",
                             path=path, dataset="[model].effects")
    exclude = _name_list(model.get("exclude", []), path=path, where="[model].exclude")
    for name in exclude:
        if name not in effects.DECLARED:
            raise InputError(f"{_show(name)} is not a declared parameter; known: {', '.join(effects.DECLARED)}",
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
                    effects=further, exclude=exclude, solver=dict(solver))
