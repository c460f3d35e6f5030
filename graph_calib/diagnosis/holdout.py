"""The loop's held-out guard: an effect is adopted only when it does not make the held-out figures worse.

On a record without a table (a hand-held session), a score test that passes at the loop's ``alpha`` may still
fit the record's few poses rather than the sensor (issue 22: one fold of a six-face session gained
``accel.nonlinearity``, passed, and its held-out transitions grew from 1.27 to 6.8 deg).  Before the loop adds
an effect there, it cross-validates the current model and the grown one on the same two folds
(:func:`graph_calib.evaluation.crossval.cross_validate`, by pairs of rests; ``calibrate`` with the primary
solver, the variance components, no structure tests) and adopts the effect only when neither pooled held-out
figure of IMU-TK's, the transitions' rms and the static |f| spread, is larger with it (:data:`GUARDED`).  A
record whose rests are too few for two folds of two, or whose folds cannot be calibrated, cannot show that an
effect holds out: the effect is not adopted there, and the check says why (issue 22: an effect is kept only when
it also improves the held-out figures).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from graph_calib.compensation.calibration import Calibration
from graph_calib.errors import InputError
from graph_calib.evaluation.crossval import cross_validate, make_folds, record_rests
from graph_calib.records.problem import build_problem
from graph_calib.solvers.concurrent import run_both
from graph_calib.solvers.orchestration import run_solvers
from graph_calib.solvers.variance import weighted_problem

#: The pooled held-out figures the guard compares (the static rate is left out: on a still unit it is the
#: Earth rate and the noise, which an effect moves by chance).
GUARDED = ("transitions_rms_deg", "static_norm_std_mps2")


@dataclass(frozen=True)
class HoldOutCheck:
    """The held-out figures without and with a candidate effect.

    Attributes
    ----------
    effect : str
    before, after : dict
        Pooled held-out figures (:meth:`graph_calib.evaluation.crossval.CrossValidation.pooled`) of the
        current model and of the model with ``effect``.
    worse : tuple of str
        The :data:`GUARDED` figures the effect makes larger.
    """

    effect: str
    before: dict
    after: dict
    worse: tuple
    unjudged: str = ""

    @property
    def adopted(self):
        return not self.worse and not self.unjudged

    def text(self):
        if self.unjudged:
            return (f"not adopted: {self.unjudged}, so it cannot be judged held out (--no-holdout adopts on the "
                    "score tests alone)")
        parts = ", ".join(f"{k} {self.before[k]:.4g} -> {self.after[k]:.4g}" for k in GUARDED
                          if np.isfinite(self.before[k]) and np.isfinite(self.after[k]))
        return (f"held out (2 folds): {parts}" if self.adopted
                else f"not adopted: held out it makes {', '.join(self.worse)} worse ({parts})")

    def to_json(self):
        return {"effect": self.effect, "before": self.before, "after": self.after, "worse": list(self.worse),
                "adopted": self.adopted, **({"unjudged": self.unjudged} if self.unjudged else {})}


def held_out_check(experiment, *, options, grown, solver, folds=2):
    """:class:`HoldOutCheck` of ``grown`` (the options with the candidate) against ``options``; None when unguarded.

    Parameters
    ----------
    experiment : graph_calib.records.experiment.Experiment
    options, grown : graph_calib.options.CalibrationOptions
        The current model's and the grown model's.
    solver : str
        The registered solver that fits each fold.
    folds : int

    Returns
    -------
    HoldOutCheck or None
        None for a record with a table (never guarded); a check with ``unjudged`` (not adopted) for a record
        whose rests are too few for the folds, or whose folds cannot be calibrated.
    """
    if experiment.table is not None:
        return None
    effect = grown.model.extra_effects[-1]

    def fitter(opts):
        return lambda train: _fit(train, options=opts, solver=solver)

    rests = record_rests(experiment)
    try:
        make_folds(experiment, folds=folds, by="pairs", rests=rests)
    except InputError:
        return HoldOutCheck(effect=effect, before={}, after={}, worse=(),
                            unjudged=f"the record's {rests.shape[0]} rests are too few for {folds} folds of two")
    try:
        # the two models' cross-validations at once (a forked worker for the first; one after the other without fork)
        cv_before, cv_after = run_both(
            lambda: cross_validate(experiment, fit=fitter(options), folds=folds, by="pairs", rests=rests),
            lambda: cross_validate(experiment, fit=fitter(grown), folds=folds, by="pairs", rests=rests))
    except InputError as exc:
        return HoldOutCheck(effect=effect, before={}, after={}, worse=(),
                            unjudged=f"a fold's training record cannot be calibrated ({exc})")
    before, after = cv_before.pooled("calibrated"), cv_after.pooled("calibrated")
    worse = tuple(k for k in GUARDED if np.isfinite(before[k]) and np.isfinite(after[k]) and after[k] > before[k])
    return HoldOutCheck(effect=effect, before=before, after=after, worse=worse)


def _fit(train, *, options, solver):
    """A fold's calibration as ``calibrate`` makes it with one solver and no structure tests (the layers below
    ``graph_calib.calibrate``, which imports this package: the variance components, then the solve)."""
    weighted = weighted_problem(build_problem(train, options=options), options=options, solver=solver)
    run = run_solvers(weighted.problem, options=replace(options, structure_tests=False), solvers=(solver,),
                      initial=weighted.initial)
    return Calibration.from_result(run.results[solver])


__all__ = ["GUARDED", "HoldOutCheck", "held_out_check"]
