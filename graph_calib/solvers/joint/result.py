"""The joint solver's result file: the result layout of ``data-format.md`` at ``t0``, extended by a ``joint`` block.

At ``T_ref = t0`` the Taylor expansion of a polynomial curve is its own coefficients, so the standard
part of the file *is* the joint calibration: ``t_ref_degC`` is ``t0``, ``estimates`` hold every curve's
coefficients under the registry's names (``gyro.bias.x`` = ``c_0``, ``gyro.bias_tc.x`` = ``c_1``,
``gyro.bias_tc2.x`` = ``c_2``, ...) and the shared elements, ``covariance`` is their joint marginal
covariance.  A reader that knows only the result layout evaluates the curves correctly about ``t0``.
The set-up parameters differ per experiment and live in the extension.  ``docs/joint-result.md``
documents the ``joint`` block.
"""

from __future__ import annotations

from math import comb

import numpy as np

from graph_calib import io
from graph_calib.sensors.effects import EFFECTS
from graph_calib.errors import InputError
from graph_calib.model.residual_list import MEASUREMENT_KINDS
from graph_calib.records.experiment import Result
from graph_calib.solvers.joint.solver import JOINT
from graph_calib.solvers.joint.unknowns import family_member
from graph_calib.sensors.params import split_element_name
from graph_calib.solvers.results import residual_block
from graph_calib.solvers.verdict import verdict_of

#: Value of the ``joint.curve_form`` key.
CURVE_FORM = "polynomial"
#: Version of the ``joint`` block.
JOINT_BLOCK_VERSION = 1


def _coefficient_element(label):
    """``gyro.bias.x:c2`` -> ``gyro.bias_tc2.x``; a shared element's name unchanged."""
    if ":c" not in label:
        return label
    flat, j = label.rsplit(":c", 1)
    p, el = split_element_name(flat)
    m = family_member(p, int(j))
    return m if el is None else f"{m}.{el}"


def joint_result(output, *, source, experiments, t_refs, sensor_ranges):
    """The :class:`graph_calib.records.experiment.Result` of a :class:`graph_calib.solvers.joint.JointOutput`.

    Parameters
    ----------
    output : graph_calib.solvers.joint.JointOutput
    source : str
        The campaign (manifest file name).
    experiments : sequence of str
        Experiment names, in the order of ``output.outputs``.
    t_refs : sequence of float
        Their reference temperatures, degC.
    sensor_ranges : sequence of array_like (6, 2)
        Their sensor temperature ranges, degC (gyro x, y, z, accel x, y, z).
    """
    u = output.unknowns
    nz = u.nz
    z_elements = [_coefficient_element(n) for n in u.z_names]
    sig = np.sqrt(np.clip(np.diag(output.covariance), 0.0, None))
    ranges = np.asarray([np.asarray(r, dtype=float).reshape(6, 2) for r in sensor_ranges])
    lo, hi = float(ranges[:, :, 0].min()), float(ranges[:, :, 1].max())
    sensor_span = np.column_stack([ranges[:, :, 0].min(axis=0), ranges[:, :, 1].max(axis=0)])
    curves = {}
    for flat in u.curve_elements():
        cols = u.curve_columns(flat)
        curves[flat] = {"degree": len(cols) - 1, "coefficients": output.theta[cols].tolist(),
                        "covariance": output.covariance[np.ix_(cols, cols)].tolist()}
    setups = {}
    for e, name in enumerate(experiments):
        sl = output.setup_slice(e)
        setups[name] = {"t_ref_degC": float(t_refs[e]),
                        "estimates": {n: {"value": float(output.theta[sl][i]), "sigma": float(sig[sl][i])}
                                      for i, n in enumerate(u.setup_names[e])}}
    blocks = [residual_block(o) for o in output.outputs]
    chi2 = [b["chi2_per_dof"] for b in blocks]
    counts = [sum(3 * n for k, n in b["counts"].items() if k in MEASUREMENT_KINDS) for b in blocks]
    kinds = sorted({k for b in blocks for k in b["counts"]})
    residuals = {"quantity": output.outputs[0].residual_quantity,
                 "counts": {k: int(sum(b["counts"].get(k, 0) for b in blocks)) for k in kinds},
                 "chi2_per_dof": float(np.dot(chi2, counts) / max(sum(counts), 1)),
                 "iterations": int(output.iterations), "converged": bool(output.converged),
                 "final_cost": float(output.final_cost), "seconds": float(output.seconds),
                 "experiments": dict(zip(experiments, blocks))}
    block = {
        "version": JOINT_BLOCK_VERSION, "curve_form": CURVE_FORM, "t0_degC": float(u.t0_degC),
        "degrees": dict(u.degrees), "degree_choice": [c.to_json() for c in output.degree_choices],
        "n_measurements": int(output.n_measurements),
        "valid_range_degC": [lo, hi],
        "sensor_ranges_degC": sensor_span.tolist(),
        "curves": curves,
        "experiments": list(experiments),
        "setups": setups,
        "unknowns": {"names": list(output.theta_names), "covariance": output.covariance.tolist()},
    }
    result = Result(source=source, solver=output.outputs[0].solver, t_ref_degC=float(u.t0_degC),
                    temperature_range_degC=(lo, hi), effects=_effects(z_elements),
                    values=dict(zip(z_elements, output.theta[:nz].tolist())),
                    sigmas=dict(zip(z_elements, sig[:nz].tolist())), covariance_names=tuple(z_elements),
                    covariance=output.covariance[:nz, :nz].copy(), residuals=residuals, extra={JOINT: block})
    # the verdict fields every result's verdict carries (converged; residuals consistent with the noise model)
    result.extra["verdict"] = verdict_of({result.solver: result}).to_json()
    return result


def joint_element_at(result, flat, t_ref_degC, *, experiment=None):
    """A per-experiment element as the joint calibration gives it at ``t_ref_degC``: ``(value, sigma)``.

    A curve family's member of order ``k`` (``gyro.bias_tc.x``: ``k = 1``) is the curve's ``k``-th Taylor
    coefficient at ``t_ref_degC``, with its sigma from the coefficients' covariance; a shared element is
    the joint estimate; a set-up element is ``experiment``'s.  None when the joint does not hold it.
    """
    block = result.extra[JOINT]
    p, el = split_element_name(flat)
    eff = EFFECTS[p]
    base = eff.temperature_of or p
    bflat = base if el is None else f"{base}.{el}"
    if bflat in block["curves"]:
        cv = block["curves"][bflat]
        c = np.asarray(cv["coefficients"], dtype=float)
        C = np.asarray(cv["covariance"], dtype=float)
        k = eff.temperature_order
        d = float(t_ref_degC) - float(block["t0_degC"])
        row = np.array([comb(j, k) * d ** (j - k) if j >= k else 0.0 for j in range(c.size)])
        return float(row @ c), float(np.sqrt(max(row @ C @ row, 0.0)))
    if experiment is not None:
        est = (block["setups"].get(experiment) or {}).get("estimates", {})
        if flat in est:
            return float(est[flat]["value"]), float(est[flat]["sigma"])
    if flat in result.values:
        return float(result.values[flat]), float(result.sigmas[flat])
    return None


def _effects(elements):
    out = []
    for n in elements:
        p = split_element_name(n)[0]
        if p not in out:
            out.append(p)
    return tuple(out)


def write_joint_result(result, path):
    """Write a joint result (:func:`joint_result`) atomically, validated like every result file."""
    io.write_result(result, path)


def read_joint_result(path):
    """Read a joint result file: a result file whose ``joint`` block is there and well formed.

    Raises
    ------
    InputError
        Naming the file and the key: not a result file, no ``joint`` block, a newer block version, a curve
        whose coefficients or covariance do not match its degree.
    """
    r = io.read_result(path)
    block = r.extra.get(JOINT)
    if not isinstance(block, dict):
        raise InputError("not a joint result (no 'joint' block: a per-experiment result?)", path=path,
                         dataset=JOINT)
    v = block.get("version")
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= JOINT_BLOCK_VERSION:
        raise InputError(f"version {v!r} is not one this graph-calib reads (up to {JOINT_BLOCK_VERSION})",
                         path=path, dataset="joint.version")
    if block.get("curve_form") != CURVE_FORM:
        raise InputError(f"curve form {block.get('curve_form')!r} is not {CURVE_FORM!r}", path=path,
                         dataset="joint.curve_form")
    for key in ("t0_degC", "curves", "valid_range_degC", "sensor_ranges_degC", "setups"):
        if key not in block:
            raise InputError("missing", path=path, dataset=f"joint.{key}")
    for name, cv in block["curves"].items():
        try:
            c = np.asarray(cv["coefficients"], dtype=float)
            C = np.asarray(cv["covariance"], dtype=float)
        except (KeyError, TypeError, ValueError):
            raise InputError("needs numeric coefficients and covariance", path=path,
                             dataset=f"joint.curves.{name}") from None
        if c.shape != (int(cv.get("degree", -1)) + 1,) or C.shape != (c.size, c.size) or not np.all(np.isfinite(C)):
            raise InputError(f"coefficients {c.shape} and covariance {C.shape} do not match degree "
                             f"{cv.get('degree')!r}", path=path, dataset=f"joint.curves.{name}")
    return r


__all__ = ["CURVE_FORM", "JOINT_BLOCK_VERSION", "joint_result", "joint_element_at", "write_joint_result", "read_joint_result"]
