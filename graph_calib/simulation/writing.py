r"""Writing a simulation: the experiment files, their truth and the campaign manifest.

:func:`write_simulation` makes the experiments of a
:class:`~graph_calib.simulation.scenarios.Simulation` one at a time and writes
each as ``<stem>.h5`` with ``<stem>.truth.json`` next to it, then the
``campaign.toml`` of :func:`manifest_text`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from graph_calib import io
from graph_calib.errors import InputError


def _toml_str(s):
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def manifest_text(simulation, *, tag=""):
    """The ``campaign.toml`` of a simulation (data-format.md; ``[model] exclude`` without a table)."""
    lines = [f"# written by graph-calib simulate {simulation.scenario}" + (f" ({tag})" if tag else ""),
             "# truth of each experiment: <file stem>.truth.json next to it", "",
             "[imu]", f"id = {_toml_str(simulation.imu_id)}", f"grade = {_toml_str(simulation.grade)}", ""]
    if simulation.exclude:
        lines += ["[model]", "exclude = [" + ", ".join(_toml_str(n) for n in simulation.exclude) + "]", ""]
    for p in simulation.plans:
        lines += ["[[experiment]]", f"file = {_toml_str(p.file_name)}", ""]
    return "\n".join(lines)


def write_simulation(simulation, out_dir, *, progress=None, tag=""):
    """Make every experiment of a simulation and write it, one at a time.

    Writes ``<stem>.h5`` (:func:`graph_calib.io.write_experiment`),
    ``<stem>.truth.json`` (:func:`graph_calib.io.write_result`) per experiment,
    then ``campaign.toml``; every file atomically.

    Parameters
    ----------
    simulation : Simulation
    out_dir : str or Path
        Created if missing.
    progress : callable, optional
        Called with a short message before each experiment.
    tag : str
        Written in the manifest's header comment.

    Returns
    -------
    list of dict
        Per experiment: ``file``, ``truth`` (paths), ``n_samples``, ``hours``,
        ``temperature_range_degC``, ``t_ref_degC``, ``table_readings``,
        ``valid_readings``, ``n_parameters``; and a last entry ``{"manifest": path}``.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc}", path=out) from None
    if not out.is_dir():
        raise InputError("is not a folder", path=out)
    summary = []
    for i, plan in enumerate(simulation.plans):
        if progress is not None:
            progress(f"[{i + 1}/{len(simulation.plans)}] simulating {plan.file_name} ({plan.summary})")
        se = plan.run()
        io.write_experiment(se.experiment, out / se.file_name)
        io.write_result(se.truth, out / se.truth_name)
        e = se.experiment
        summary.append({
            "file": out / se.file_name, "truth": out / se.truth_name, "n_samples": e.n_samples,
            "hours": e.n_samples / e.rate_hz / 3600.0, "rate_hz": e.rate_hz,
            "temperature_range_degC": se.truth.temperature_range_degC, "t_ref_degC": se.truth.t_ref_degC,
            "table_readings": 0 if e.table is None else int(e.table.t.size),
            "valid_readings": 0 if e.table is None else int(np.count_nonzero(e.table.valid)),
            "n_parameters": len(se.truth.values),
        })
        del se
    manifest = out / "campaign.toml"
    io.atomic_write_text(manifest, manifest_text(simulation, tag=tag))
    summary.append({"manifest": manifest})
    return summary


__all__ = ["manifest_text", "write_simulation"]
