"""The waves of the campaign's pooled score test: decide, solve again what gained an effect, decide again.

After the first wave of jobs (every experiment's own closed loop, :mod:`graph_calib.campaign.execution`) the
main process reads each experiment's loop record (its final round's candidate statistics, kept in its result
files: nothing is recomputed), runs the pooled test (:mod:`graph_calib.campaign.pooled`) and, when an effect
passes, sends a wave of jobs: each experiment that adopts it, solved again with it by both of the campaign's
solvers, warm-started from its previous results (:func:`graph_calib.diagnosis.diagnose_from`), its files in
``<experiment>/pooled/<wave>/``.  Then the pooled test again on the new final rounds, until nothing passes or
:data:`graph_calib.campaign.pooled.MAX_WAVES` waves have run.  When nothing passes, a curvature term
(``*_tc2``, ``*_tc3``) that some experiment adopted is carried, in a wave of its own, into the experiments
whose model lacks it (:func:`carried_curvature`): one IMU has one curve over the range.

A wave's tasks are cached and resumable like the first wave's: the key covers the grown model's options (the
adopted effects), the loop's options and the keys of the results it starts from; a campaign run again with
everything cached replays the same decisions from the records and recomputes nothing.  They run on the same
executor as the first wave (this process, a local Dask cluster or an existing scheduler).
"""

from __future__ import annotations

import hashlib
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from graph_calib import io
from graph_calib.campaign.execution import execute
from graph_calib.campaign.pooled import MAX_WAVES, RULE, adoption, decision_text, final_statistics, pooled_tests
from graph_calib.campaign.tasks import Task, cached, options_sha256, task_key
from graph_calib.sensors.effects import EFFECTS

#: Where a wave's files go, under the experiment's folder: ``pooled/<wave>/``.
POOLED_FOLDER = "pooled"


@dataclass
class _State:
    """An experiment as the pooled test sees it: its current results, their folder and loop record."""

    tasks: list
    folder: Path
    results: dict
    record: dict
    pooled: list = field(default_factory=list)


@dataclass(frozen=True)
class PooledRun:
    """What the waves did.

    Attributes
    ----------
    folders : dict
        ``{experiment: folder}`` (relative to the output folder) of the experiments whose final results are a
        wave's (``<name>/pooled/<wave>``); the others' stay in ``<name>/``.
    outcomes : dict
        ``{(experiment, solver): outcome}`` of the waves' tasks (the last wave that touched each).
    document : dict
        ``campaign.json``'s ``loop.pooled``: ``rule``, ``alpha``, ``max_waves``, ``waves`` (per wave every
        candidate's pooled test, the adopted one and the decision), ``seconds``, ``tasks_computed``,
        ``tasks_cached``, ``tasks_failed``.
    adopted : dict
        ``{experiment: [pooled test dict with its "wave"]}``, what the pooled test adopted in each.
    states : dict
        ``{experiment: _State}``: each experiment's current results, folder and loop record, where a later
        wave starts (:mod:`graph_calib.campaign.curvature_wave`).
    """

    folders: dict
    outcomes: dict
    document: dict
    adopted: dict
    states: dict = field(default_factory=dict)


def _start_key(results):
    """One hash of the keys of the results a wave starts from (their solvers in order)."""
    text = "|".join(f"{s}:{(r.extra.get('campaign') or {}).get('key', '')}" for s, r in sorted(results.items()))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def wave_tasks(state, *, name, effects, wave, dopts, prior_sigma=None, prior_mean=None):
    """The tasks of one experiment in a wave: its model grown by ``effects``, started from its current results.

    ``prior_sigma``, ``prior_mean``: ``{parameter: per-element values}`` the grown model's priors take (the joint
    curve's curvature, :mod:`graph_calib.campaign.curvature_wave`); None: the grade's.
    """
    base = state.tasks[0].options
    rec = state.record
    added = tuple(n for n in rec["chosen"] if n not in rec["declared"])
    t_ref = next(iter(state.results.values())).t_ref_degC
    model = replace(base.model, extra_effects=tuple(base.model.extra_effects) + added + tuple(effects))
    if prior_sigma:
        model = replace(model, prior_sigma={**(model.prior_sigma or {}), **prior_sigma})
    if prior_mean:
        model = replace(model, prior_mean={**(model.prior_mean or {}), **prior_mean})
    copts = replace(base, model=model, t_ref_degC=float(t_ref))
    osha = hashlib.sha256(f"{options_sha256(copts, dopts)}|wave {wave}|start {_start_key(state.results)}"
                          .encode("utf-8")).hexdigest()
    out_dir = state.tasks[0].out_dir
    return [Task(name=name, file=t.file, solver=t.solver, options=copts,
                 out_dir=str(Path(out_dir) / POOLED_FOLDER / str(wave)),
                 key=task_key(input_sha256=t.input_sha256, options_sha256=osha, solver=t.solver),
                 input_sha256=t.input_sha256, options_sha256=osha, numba_threads=t.numba_threads, diagnosis=dopts,
                 wave=wave, start_dir=str(state.folder), pooled=tuple(state.pooled) + tuple(effects),
                 wave_effects=tuple(effects))
            for t in state.tasks]


@dataclass(frozen=True)
class CarriedCurvature:
    """A curvature term adopted somewhere, carried into the experiments whose model lacks it.

    An IMU's temperature curve is one curve over the campaign: when some experiment's loop (or a pooled
    wave) adopted a family's ``*_tc2`` (``*_tc3``), the other subranges have that curvature too, unresolved
    by their own records, and their linear models absorb it into ``p`` and ``p_tc`` (biased estimates, the
    campaign's check "curvature carried", :mod:`graph_calib.campaign.checks`).  The lowest such order missing
    anywhere is carried first, one order per wave.
    """

    effect: str
    experiments: tuple
    sources: tuple
    kind: str = "carried"

    def to_json(self):
        return {"effect": self.effect, "kind": self.kind, "experiments": list(self.experiments),
                "adopted_in": list(self.sources), "statistic": None, "dof": None, "threshold": None,
                "log10_p": None}

    def text(self):
        return (f"carried {self.effect} into {', '.join(self.experiments)}: the curvature "
                f"{', '.join(self.sources)} adopted is the same IMU's curve there")


def carried_curvature(states, *, covered=None):
    """The curvature term to carry next (:class:`CarriedCurvature`), or None when every experiment has it.

    ``covered``: ``effect -> bool``, the orders the joint curves carry (:meth:`JointCarry.covers
    <graph_calib.campaign.curvature_wave.JointCarry.covers>`), which are left to them.
    """
    chosen = {n: set(st.record.get("chosen") or ()) for n, st in states.items()}
    candidates = sorted({c for names in chosen.values() for c in names
                         if EFFECTS.get(c) is not None and EFFECTS[c].temperature_order >= 2
                         and not (covered is not None and covered(c))},
                        key=lambda c: (EFFECTS[c].temperature_order, c))
    for c in candidates:
        lacking = tuple(n for n in states if c not in chosen[n])
        if lacking:
            return CarriedCurvature(effect=c, experiments=lacking,
                                    sources=tuple(n for n in states if c in chosen[n]))
    return None


def _states(planned, outcomes):
    """``{experiment: _State}`` of every experiment whose first-wave tasks all finished with the loop."""
    tasks = {}
    for t in list(planned.todo) + list(planned.done):
        tasks.setdefault(t.name, []).append(t)
    states = {}
    for e in planned.campaign.experiments:
        ts = tasks.get(e.name, [])
        if not ts or any(outcomes.get((e.name, t.solver), {}).get("status") not in ("computed", "cached")
                         for t in ts):
            continue
        results = {t.solver: io.read_result(t.result_path) for t in ts}
        rec = (next(iter(results.values())).extra.get("campaign") or {}).get("loop")
        if rec is None:
            continue
        states[e.name] = _State(tasks=ts, folder=Path(ts[0].out_dir), results=results, record=rec)
    return states


def run_waves(planned, outcomes, *, options, on_done=None, pool=None, carry=None):
    """The pooled score test and its waves after the first wave of jobs (module docstring).

    Parameters
    ----------
    planned : graph_calib.campaign.planning.CampaignPlan
    outcomes : dict
        ``{(experiment, solver): outcome}`` of the first wave (computed or cached).
    options : CampaignOptions
    on_done : callable, optional
        Called with each finished wave task's outcome, as in the first wave.
    pool : graph_calib.campaign.execution.Pool, optional
        The first wave's cluster, kept (default: each wave starts its own).
    carry : graph_calib.campaign.curvature_wave.JointCarry, optional
        The joint curves, when the joint was solved and its verdict passed: each experiment a wave solves
        again also gets the orders of the joint curves its model lacks, with the joint's priors, and a
        curvature term the joint carries is not carried here (:func:`carried_curvature`).

    Returns
    -------
    PooledRun or None
        None when the loop is off (``--no-diagnose``): no pooled test either.
    """
    tasks = list(planned.todo) + list(planned.done)
    dopts = tasks[0].diagnosis if tasks else None
    if dopts is None:
        return None
    t0 = time.perf_counter()
    states = _states(planned, outcomes)
    waves, wave_outcomes, adopted, folders = [], {}, {}, {}
    counts = {"computed": 0, "cached": 0, "failed": 0}
    for wave in range(1, MAX_WAVES + 2):
        tests = pooled_tests({n: final_statistics(st.record) for n, st in states.items()}, alpha=dopts.alpha,
                             identifiable=dopts.identifiable)
        pick = adoption(tests) or carried_curvature(states, covered=carry.covers if carry else None)
        limit = pick is not None and wave > MAX_WAVES
        text = (f"{pick.effect} passes but the limit of {MAX_WAVES} pooled waves is reached" if limit
                else pick.text() if isinstance(pick, CarriedCurvature) else decision_text(tests, pick))
        waves.append({"wave": wave, "tests": [t.to_json() for t in tests],
                      "adopted": None if pick is None or limit else pick.to_json(), "decision": text})
        if options.progress:
            print(f"pooled score test {wave}: {text}", file=sys.stderr, flush=True)
        if pick is None or limit:
            break
        new, adoptions, priors = [], {}, {}
        for n in pick.experiments:
            # the adopted effect with the grade's prior, as the test adopted it; the joint's other orders with theirs
            joint = carry.priors(next(iter(states[n].results.values()))) if carry else {}
            joint.pop(pick.effect, None)
            new += wave_tasks(states[n], name=n, effects=(pick.effect,) + tuple(joint), wave=wave, dopts=dopts,
                              prior_sigma={e: s for e, (_, s) in joint.items()} or None,
                              prior_mean={e: m for e, (m, _) in joint.items()} or None)
            adoptions[n] = [dict(pick.to_json(), wave=wave)] + [
                carry.adoption(e, wave=wave, experiments=(n,)) for e in joint]
            if joint:
                priors[n] = {e: {"mean": m, "sigma": s} for e, (m, s) in joint.items()}
        if priors:
            waves[-1]["priors"] = priors       # the joint curves' orders carried along, as the joint wave's
        run = PooledRun(folders=folders, outcomes=wave_outcomes, document={}, adopted=adopted, states=states)
        execute_wave(run, new, adoptions, wave=wave, options=options, on_done=on_done, pool=pool, counts=counts)
    document = {"rule": RULE, "alpha": dopts.alpha, "max_waves": MAX_WAVES, "waves": waves,
                "seconds": time.perf_counter() - t0, "tasks_computed": counts["computed"],
                "tasks_cached": counts["cached"], "tasks_failed": counts["failed"]}
    return PooledRun(folders=folders, outcomes=wave_outcomes, document=document, adopted=adopted, states=states)


def execute_wave(run, tasks, adoptions, *, wave, options, on_done, pool, counts):
    """A wave's tasks run (or read from the cache) and ``run``'s maps updated in place.

    Parameters
    ----------
    run : PooledRun
        Its ``folders``, ``outcomes``, ``adopted`` and ``states`` are updated: each experiment of ``adoptions``
        has its results, record and folder the wave's (an experiment a task of which failed leaves ``states``:
        its failure is reported, it takes no further part).
    tasks : list of Task
        The wave's tasks (:func:`wave_tasks`).
    adoptions : dict
        ``{experiment: [adoption dict]}``, what ``campaign.json``'s ``loop.pooled`` lists for it from this wave.
    wave : int
    options : CampaignOptions
    on_done, pool
        As for :func:`run_waves`.
    counts : dict
        ``{"computed", "cached", "failed": int}``, counted on.
    """
    todo = [t for t in tasks if options.force or not cached(t)]
    outs = execute(todo, options=options, on_done=on_done, pool=pool)
    for t in tasks:
        if t not in todo:
            outs[(t.name, t.solver)] = {"name": t.name, "solver": t.solver, "status": "cached"}
    for n, entries in adoptions.items():
        mine = [t for t in tasks if t.name == n]
        oc = {t.solver: outs[(t.name, t.solver)] for t in mine}
        for t in mine:
            run.outcomes[(n, t.solver)] = oc[t.solver]
            counts["failed" if oc[t.solver]["status"] == "failed" else oc[t.solver]["status"]] += 1
        run.adopted.setdefault(n, []).extend(entries)
        run.folders[n] = Path(n) / POOLED_FOLDER / str(wave)
        if any(o["status"] == "failed" for o in oc.values()):
            del run.states[n]
            continue
        st = run.states[n]
        st.results = {t.solver: io.read_result(t.result_path) for t in mine}
        st.record = next(iter(st.results.values())).extra["campaign"]["loop"]
        st.folder = Path(mine[0].out_dir)
        st.pooled.extend(mine[0].added_by_wave)


__all__ = ["POOLED_FOLDER", "PooledRun", "CarriedCurvature", "carried_curvature", "run_waves", "wave_tasks",
           "execute_wave"]
