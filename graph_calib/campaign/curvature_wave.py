r"""The joint curve's curvature carried into the subranges that lack it: the campaign's last wave of re-solves.

An IMU's temperature dependence is one curve over the campaign.  The joint solver
(:mod:`graph_calib.solvers.joint`) fits it per family over the whole range, at the degree its Wald test chose;
a subrange whose own record (1.5 h, a few degC) cannot resolve that curvature keeps a model without it, and
its linear estimates absorb the orders it lacks: under a cubic truth the 20..30 degC subrange's
``accel.bias.y`` came out 4.4 sigma off, unflagged (issue 23).  The pooled score tests
(:mod:`graph_calib.campaign.pooled`) carry curvature a loop adopted somewhere; what only the joint's degree
shows (the scale factors' curvature, typically) stays missing.

The joint is solved before the pooled waves, and a pooled wave that solves an experiment again adds the
orders it lacks at once (:class:`JointCarry`, :func:`graph_calib.campaign.waves.run_waves`).  Here, after the
pooled waves, every experiment whose final model still holds fewer orders of a family than the
joint's degree is solved again (both solvers, warm-started from its current results, the loop's rounds on
the grown model: a wave like the pooled test's, :func:`graph_calib.campaign.waves.execute_wave`) with the
missing orders ``*_tc2`` .. ``*_tc<d>`` added as parameters whose prior is what the campaign knows of them:

.. math::

    \text{prior of } p_{tc k} = a_k(T_{ref}) \pm \sigma_{a_k}(T_{ref}),

the joint curve's ``k``-th Taylor coefficient at the subrange's ``T_ref`` and its one sigma from the curve's
coefficient covariance (:func:`graph_calib.sensors.curves.taylor_at`; a diagonal prior, each element its
own).  The subrange's data still judge them (the joint curve's uncertainty is carried into the subrange's
covariance, not assumed away); what a short record cannot determine comes from the campaign.  The joint
uses the subrange's own data too, so its curvature and the subrange's estimate are slightly correlated:
the curvature is determined by the spread over all subranges, of which one subrange's own record is a small
share.

An experiment whose estimates the orders it lacks would shift by less than :data:`CARRY_SIGMA` of their
sigmas (the offsets of the check "curvature carried", :func:`graph_calib.campaign.checks.curvature_bias`) is
not solved again: its re-solve would cost as much as its first solve and change nothing that matters (long
subranges resolve most of their curvature themselves).  After this wave every other final per-subrange result
holds every order of the joint curves, so the campaign's check "curvature carried"
(:mod:`graph_calib.campaign.checks`) has nothing left to flag beyond those small offsets; the truth check and
the joint-against-subranges check judge the results the wave wrote.  A task of the wave that fails is
reported like every failed task of a pooled wave (``campaign.json``'s ``failed``, exit 1).  A joint result whose
verdict failed (not converged, residuals inconsistent) is no prior: nothing is carried, the wave's entry says
why, and the check "curvature carried" flags the subranges lacking its orders as before.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, replace

import numpy as np

from graph_calib.campaign.checks import curvature_bias, orders_held
from graph_calib.campaign.waves import execute_wave, wave_tasks
from graph_calib.sensors.curves import taylor_at
from graph_calib.sensors.effects import EFFECTS, temperature_family
from graph_calib.solvers.joint.solver import JOINT

#: ``campaign.json``'s kind of the adoptions this wave makes (``loop.pooled``).
KIND = "joint"
#: An experiment whose estimates the orders it lacks shift by less than this many of their sigmas (the check's
#: offsets, :func:`graph_calib.campaign.checks.curvature_bias`) is not solved again: the re-solve costs as much
#: as its first solve and would move nothing that matters (half a sigma at most: a 3-sigma tail of 0.6 %
#: instead of 0.3 %); the check reports what it lacks.
CARRY_SIGMA = 0.5


def joint_priors(joint, result):
    """The orders of the joint curves ``result``'s model lacks, with their priors at its ``T_ref``.

    Parameters
    ----------
    joint : graph_calib.records.experiment.Result
        The joint result (its ``extra["joint"]`` block: ``t0_degC``, ``degrees``, ``curves``).
    result : graph_calib.records.experiment.Result
        One experiment's current final result.

    Returns
    -------
    dict
        ``{effect: (means, sigmas)}`` per element (SI), lowest order first; empty when ``result`` holds every
        order of every joint curve (or a curve's element is missing from the joint).
    """
    block = joint.extra[JOINT]
    t0 = float(block["t0_degC"])
    out = {}
    for family, degree in block["degrees"].items():
        _, orders = temperature_family(family)
        for k in range(orders_held(result, family) + 1, int(degree) + 1):
            name = orders.get(k)
            if name is None:
                continue
            curves = [block["curves"].get(f"{family}.{el}") for el in EFFECTS[name].elements]
            if any(cv is None for cv in curves):
                continue
            means, sigmas = [], []
            for cv in curves:
                a, C = taylor_at(cv["coefficients"], result.t_ref_degC, t0_degC=t0, covariance=cv["covariance"])
                means.append(float(a[k]))
                sigmas.append(float(np.sqrt(max(C[k, k], 0.0))))
            if min(sigmas) > 0:
                out[name] = (means, sigmas)
    return out


def _adoption(effect, *, wave, experiments, degree):
    return {"effect": effect, "kind": KIND, "wave": wave, "experiments": list(experiments),
            "adopted_in": [f"the joint's degree {degree}"], "statistic": None, "dof": None, "threshold": None,
            "log10_p": None}


@dataclass(frozen=True)
class JointCarry:
    """The joint curves' orders, carried into every re-solve of a pooled wave (:func:`joint_carry`).

    A pooled wave (:func:`graph_calib.campaign.waves.run_waves`) solves an experiment again anyway; with this
    it also adds the joint curves' orders the experiment's model lacks, each with its prior from the joint
    (:func:`joint_priors`), so that the experiment is not solved once more by this module's wave.

    Attributes
    ----------
    joint : graph_calib.records.experiment.Result
        The joint result; its verdict passed.
    """

    joint: object

    def priors(self, result):
        """:func:`joint_priors` of ``result``."""
        return joint_priors(self.joint, result)

    def covers(self, effect):
        """Whether ``effect`` is an order of a family the joint fits, at most its degree (this wave carries it)."""
        e = EFFECTS.get(effect)
        if e is None or e.temperature_of is None:
            return False
        degree = self.joint.extra[JOINT]["degrees"].get(e.temperature_of)
        return degree is not None and e.temperature_order <= int(degree)

    def adoption(self, effect, *, wave, experiments):
        """``campaign.json``'s entry of ``effect`` carried in ``wave`` into ``experiments``."""
        degree = self.joint.extra[JOINT]["degrees"][EFFECTS[effect].temperature_of]
        return _adoption(effect, wave=wave, experiments=experiments, degree=degree)


def joint_carry(joint):
    """A :class:`JointCarry` of ``joint``, or None when there is no joint result or its verdict failed (a
    joint curve that did not converge or does not explain its data is no prior)."""
    if joint is None or not (joint.extra.get("verdict") or {}).get("passed", True):
        return None
    return JointCarry(joint=joint)


def run_curvature_wave(planned, pooled, joint, *, options, on_done=None, pool=None, sensor_ranges=None):
    """The wave of re-solves carrying the joint curves' missing orders (module docstring).

    Parameters
    ----------
    planned : graph_calib.campaign.planning.CampaignPlan
    pooled : graph_calib.campaign.waves.PooledRun or None
        The pooled waves' run (None without the loop: nothing is re-solved, the check flags).
    joint : graph_calib.records.experiment.Result or None
        The joint result (None: nothing to carry).
    options : CampaignOptions
    on_done, pool
        As for :func:`graph_calib.campaign.waves.run_waves`.
    sensor_ranges : dict, optional
        ``{experiment: its sensors' temperature ranges}`` (the summaries'), over which the offsets the lacking
        orders cause are judged against :data:`CARRY_SIGMA` (default: each result's own range).

    Returns
    -------
    PooledRun or None
        ``pooled`` with this wave's outcomes, folders and adoptions added and its entry in the document's
        ``waves`` (``kind`` ``"joint"``); ``pooled`` itself when nothing lacks an order.
    """
    if pooled is None or joint is None or not pooled.states:
        return pooled
    t0 = time.perf_counter()
    tasks = list(planned.todo) + list(planned.done)
    dopts = tasks[0].diagnosis if tasks else None
    wave = len(pooled.document["waves"]) + 1
    degrees = joint.extra[JOINT]["degrees"]
    shifts = curvature_bias(joint, {n: st.results for n, st in pooled.states.items()}, sensor_ranges or {})
    priors, small = {}, {}
    for n, st in pooled.states.items():
        pr = joint_priors(joint, next(iter(st.results.values())))
        if not pr:
            continue
        worst = max((abs(z) for rows in shifts.get(n, {}).values() for z in rows.values()), default=0.0)
        if worst < CARRY_SIGMA:
            small[n] = worst
        else:
            priors[n] = pr
    if small:
        pooled.document.setdefault("joint_not_carried", {}).update(small)
    if not priors:
        return pooled
    verdict = joint.extra.get("verdict") or {}
    if not verdict.get("passed", True):
        # a joint curve that did not converge or does not explain its data is no prior: nothing carried, the
        # check "curvature carried" flags the subranges that lack its orders
        text = (f"the joint curves' orders not carried into {', '.join(priors)}: the joint's verdict failed "
                f"({verdict.get('text', '')})")
        pooled.document["waves"].append({"wave": wave, "kind": KIND, "tests": [], "adopted": None, "decision": text})
        if options.progress:
            print(f"joint curvature wave: {text}", file=sys.stderr, flush=True)
        return pooled
    new, adoptions = [], {}
    for n, pr in priors.items():
        new += wave_tasks(pooled.states[n], name=n, effects=tuple(pr), wave=wave, dopts=dopts,
                          prior_sigma={e: s for e, (_, s) in pr.items()},
                          prior_mean={e: m for e, (m, _) in pr.items()})
        adoptions[n] = [_adoption(e, wave=wave, experiments=tuple(priors),
                                  degree=degrees[EFFECTS[e].temperature_of]) for e in pr]
    text = ("carried the joint curves' orders the subranges lack, each with the joint's Taylor coefficient at the "
            "subrange's T_ref as its prior: " + "; ".join(f"{n}: {', '.join(pr)}" for n, pr in priors.items()))
    if small:
        text += (f"; not into {', '.join(small)} (what they lack shifts no estimate by {CARRY_SIGMA:g} sigma: at most "
                 f"{max(small.values()):.2f})")
    if options.progress:
        print(f"joint curvature wave {wave}: {text}", file=sys.stderr, flush=True)
    doc = pooled.document
    counts = {"computed": 0, "cached": 0, "failed": 0}
    execute_wave(pooled, new, adoptions, wave=wave, options=options, on_done=on_done, pool=pool, counts=counts)
    doc["waves"].append({"wave": wave, "kind": KIND, "tests": [], "decision": text,
                         "adopted": {"effect": ", ".join(sorted({e for pr in priors.values() for e in pr})),
                                     "kind": KIND, "experiments": list(priors)},
                         "priors": {n: {e: {"mean": m, "sigma": s} for e, (m, s) in pr.items()}
                                    for n, pr in priors.items()},
                         "seconds": time.perf_counter() - t0, "tasks_computed": counts["computed"]})
    for k in counts:
        doc[f"tasks_{k}"] = doc.get(f"tasks_{k}", 0) + counts[k]
    doc["seconds"] = doc.get("seconds", 0.0) + time.perf_counter() - t0
    return replace(pooled, document=doc)


__all__ = ["KIND", "CARRY_SIGMA", "JointCarry", "joint_carry", "joint_priors", "run_curvature_wave"]
