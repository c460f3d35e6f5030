"""What the loop decides with and what it records: options, the tests of a round, the stages, the diagnosis.

:class:`DiagnosisOptions` says how the loop decides; each round records its
:class:`CandidateTest` and :class:`DriverTest` results in a :class:`Round`; a
:class:`Stage` is a calibrated model (before, after) with its residual figures; a
:class:`Diagnosis` holds them all and gives ``diagnosis.json`` (``to_json``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graph_calib import constants as c
from graph_calib.sensors import effects
from graph_calib.diagnosis.drivers import DRIVER_GROUPS, TIME_SEGMENTS
from graph_calib.diagnosis.residuals import residual_rms
from graph_calib.records.experiment import Result
from graph_calib.records.problem import Problem
from graph_calib.solvers.interface import SolverOutput
from graph_calib.solvers.registry import DEFAULT_SOLVERS, primary_first
from graph_calib.solvers.verdict import Verdict


@dataclass(frozen=True)
class DiagnosisOptions:
    """How the loop decides.

    Attributes
    ----------
    alpha : float
        False-alarm probability of each decision (family-wise over the tests of
        one decision, Bonferroni): adding any effect to a correct model, or
        calling the residuals structured.  Each of the ``m`` candidate tests of
        a round is run at ``alpha / m``, each of the driver tests at
        ``alpha / m_drivers``.
    identifiable : float
        A candidate's direction counts when the data determine it at least this
        many times better in information than its prior (``lambda(D S D) >= identifiable``).
    driver_min_eig : float
        A driver direction counts when this fraction of its column's information is
        not already explained by the current model.
    max_added : int
        Most effects added.
    candidates : tuple of str or None
        Effects to test (default every further effect of model.md).
    solvers : tuple of str
        Solvers run before and after, registered names: the first solves every model the rounds test
        (the rounds linearise at its solution), the others are run on the declared and the final model
        (default: the registry's default solvers, its primary solver first).
    encompassing : bool
        Check each accepted candidate against the generic drivers (a candidate that only
        mimics a driver signature the catalogue lacks is not added).
    time_segments : int
        Cubic B-spline functions of the ``time`` driver.
    holdout : bool
        On a record without a table, adopt an effect only when it does not make the held-out figures
        worse (:mod:`graph_calib.diagnosis.holdout`; two folds, four calibrations per added effect).  On by
        default: a hand-held record's few poses let a score test pass on an effect that fits them rather than
        the sensor (docs/diagnosis.md); a record with a table is never guarded.
    """

    alpha: float = 0.01
    identifiable: float = 1.0
    driver_min_eig: float = 1e-3
    max_added: int = 4
    candidates: tuple[str, ...] | None = None
    solvers: tuple[str, ...] = primary_first(DEFAULT_SOLVERS)
    encompassing: bool = True
    time_segments: int = TIME_SEGMENTS
    holdout: bool = True


@dataclass(frozen=True)
class CandidateTest:
    """The score test of one further effect in one round.

    Attributes
    ----------
    name : str
        The effect (``model.md``).
    statistic : float
        Score statistic (0 when skipped).
    dof, dim : int
        Identifiable directions, and the effect's elements.
    threshold : float
        Chi-square quantile at ``alpha / m`` (NaN when skipped).
    log10_p : float
    significant : bool
    skipped : str or None
        Why the effect was not tested (not estimable in this experiment, not identifiable).
    estimate, sigma : tuple of float
        One-step estimate of its elements and their sigmas, SI (empty when skipped).
    score, information, scale : tuple of float
        The score ``u`` (dim), its information ``S`` (dim x dim, row-major) and the prior sigmas that judge
        which directions are identifiable, SI, ``u`` and ``S`` divided by the variance factor
        (:class:`~graph_calib.diagnosis.score.Score`); empty when skipped.  Not in ``diagnosis.json``; a
        campaign keeps them for its pooled test (``graph_calib.campaign.loop.loop_record``).
    """

    name: str
    statistic: float
    dof: int
    dim: int
    threshold: float
    log10_p: float
    significant: bool
    skipped: str | None
    estimate: tuple[float, ...]
    sigma: tuple[float, ...]
    score: tuple[float, ...] = ()
    information: tuple[float, ...] = ()
    scale: tuple[float, ...] = ()

    def to_json(self):
        s = effects.effect(self.name)
        d = {"name": self.name, "statistic": self.statistic, "dof": self.dof, "dim": self.dim,
             "threshold": self.threshold, "log10_p": self.log10_p, "significant": self.significant}
        if self.skipped:
            d["skipped"] = self.skipped
        else:
            d["estimate"] = dict(zip(s.element_names(), self.estimate))
            d["sigma"] = dict(zip(s.element_names(), self.sigma))
            d["report_unit"] = s.report_unit
        return d


@dataclass(frozen=True)
class DriverTest:
    """The score test of one generic driver group placed as a bias on one sensor axis.

    Attributes
    ----------
    group : str
        A key of :data:`~graph_calib.diagnosis.drivers.DRIVER_GROUPS`.
    axis : str
        One of :data:`~graph_calib.diagnosis.drivers.SENSOR_AXES`.
    labels : tuple of str
        The group's features on this axis.
    statistic, dof, threshold, log10_p, significant
        As :class:`CandidateTest` (threshold at ``alpha / m_drivers``).
    estimate, sigma : tuple of float
        One-step coefficients per feature and their sigmas (identifiable directions).
    amplitude : float
        RMS of ``profile`` (rad/s or m/s^2).
    profile : tuple of float
        Fitted bias per keyframe, mean removed (NaN where such a bias is not seen).
    """

    group: str
    axis: str
    labels: tuple[str, ...]
    statistic: float
    dof: int
    threshold: float
    log10_p: float
    significant: bool
    estimate: tuple[float, ...]
    sigma: tuple[float, ...]
    amplitude: float = 0.0
    profile: tuple[float, ...] = ()

    @property
    def unit(self):
        return "rad/s" if self.axis.startswith("gyro") else "m/s^2"

    @property
    def report(self):
        """``(unit, factor)`` for reports: deg/h for gyros, micro-g for accelerometers."""
        return ("deg/h", c.RS_TO_DH) if self.axis.startswith("gyro") else ("micro-g", c.MPS2_TO_UG)

    def strength(self):
        """``sqrt(statistic)``: the signature's size in sigmas of its own noise."""
        return float(np.sqrt(max(self.statistic, 0.0)))

    def to_json(self):
        unit, k = self.report
        return {"driver": self.group, "axis": self.axis, "meaning": DRIVER_GROUPS.get(self.group, ""),
                "statistic": self.statistic, "dof": self.dof,
                "threshold": self.threshold, "log10_p": self.log10_p, "significant": self.significant,
                "strength_sigma": self.strength(),
                "amplitude": {"rms": self.amplitude, "unit": self.unit, "rms_report": self.amplitude * k,
                              "report_unit": unit},
                "coefficients": [{"feature": lb, "value": e, "sigma": s if np.isfinite(s) else None,
                                  "unit": f"{self.unit} per unit of the feature"}
                                 for lb, e, s in zip(self.labels, self.estimate, self.sigma)]}


@dataclass(frozen=True)
class Round:
    """One round of the loop: the tests at the current model's solution and what was decided.

    Attributes
    ----------
    index : int
        From 1.
    layout : tuple of str
        The current model's parameters.
    candidates : list of CandidateTest
    drivers : list of DriverTest
    variance_factor : float
        ``s^2`` of the current fit.
    chi2_per_dof : float
    added : str or None
        The effect added in this round.
    decision : str
        The decision in words.
    checks : list of dict
        The encompassing checks of the significant candidates (``diagnosis.json``'s
        ``encompassing_checks``).
    seconds : float
    held_out : dict or None
        The held-out guard's figures for the effect the tests chose
        (:class:`graph_calib.diagnosis.holdout.HoldOutCheck`), None when not guarded.
    """

    index: int
    layout: tuple[str, ...]
    candidates: list[CandidateTest]
    drivers: list[DriverTest]
    variance_factor: float
    chi2_per_dof: float
    added: str | None = None
    decision: str = ""
    checks: list[dict] = field(default_factory=list)
    seconds: float = 0.0
    held_out: dict | None = None

    def to_json(self):
        tested = [c for c in self.candidates if not c.skipped]
        return {
            "round": self.index, "model": list(self.layout), "chi2_per_dof": self.chi2_per_dof,
            "variance_factor": self.variance_factor, "added": self.added, "decision": self.decision,
            "candidates": [c.to_json() for c in sorted(tested, key=lambda c: c.log10_p)]
            + [c.to_json() for c in self.candidates if c.skipped],
            "drivers_significant": [d.to_json() for d in sorted(self.drivers, key=lambda d: d.log10_p)
                                    if d.significant],
            "encompassing_checks": self.checks, "seconds": self.seconds,
            **({"held_out": self.held_out} if self.held_out is not None else {}),
        }


@dataclass
class Stage:
    """A calibrated model (before: declared; after: with the added effects).

    Attributes
    ----------
    layout : tuple of str
    problem : graph_calib.records.problem.Problem
    primary : str
        The solver whose solution the rounds linearise at (the first of ``DiagnosisOptions.solvers``).
    outputs : dict of str to graph_calib.solvers.interface.SolverOutput
        ``{solver: output}``, the primary's first.
    results : dict of str to graph_calib.records.experiment.Result
        ``{solver: Result}``.
    comparison : dict or None
        ``comparison.json`` of the first two solvers in comparison order, the verdict included.
    verdict : graph_calib.solvers.verdict.Verdict or None
    residuals : dict
        The primary solution's factor residuals per kind: ``t``, ``key``, ``r`` (SI), ``w`` (whitened;
        gravity also in body axes) (:func:`~graph_calib.diagnosis.residuals.factor_residuals`).
    innovations : dict
        ``{solver: {kind: {"t", "key", "w" (F, 3)}}}``: each further solver's own residual series (the
        filter's normalised innovations) with their keyframes; empty with one solver.
    statistics : dict
        :func:`~graph_calib.diagnosis.residuals.residual_statistics` of every solver.
    error : dict or None
        ``{solver: error_against_truth(...)}`` (plus ``rms_z_fixed``) when a truth is given.
    """

    layout: tuple[str, ...]
    problem: Problem
    primary: str
    outputs: dict[str, SolverOutput]
    results: dict[str, Result]
    comparison: dict | None = None
    verdict: Verdict | None = None
    residuals: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    innovations: dict[str, dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)
    statistics: dict = field(default_factory=dict)
    error: dict[str, dict] | None = None

    @property
    def solution(self):
        """The primary solver's output (the solution the rounds linearise at)."""
        return self.outputs[self.primary]


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`~graph_calib.diagnosis.loop.diagnose` found (``to_json`` gives ``diagnosis.json``).

    Attributes
    ----------
    source : str
        The experiment's file name.
    added : list of str
        The effects added, in order.
    unexplained : bool
        Whether driver tests are significant at the final model.
    signature : list of DriverTest
        Those driver tests, most significant first.
    rounds : list of Round
    before, after : Stage
        The declared model and the final one (the same object when nothing was added).
    options : DiagnosisOptions
    context : dict
        The experiment and the run (``diagnosis.json``'s ``context``).
    seconds : float
    """

    source: str
    added: list[str]
    unexplained: bool
    signature: list[DriverTest]
    rounds: list[Round]
    before: Stage
    after: Stage
    options: DiagnosisOptions
    context: dict
    seconds: float = 0.0

    def to_json(self):
        def stage(s):
            out = {"model": list(s.layout), "residual_rms": residual_rms(s), "residuals": s.statistics}
            if s.error is not None:
                out["error_vs_truth"] = s.error
            return out

        last = self.rounds[-1] if self.rounds else None
        return _finite({
            "format": "imu-calibration-diagnosis",
            "version": 1,
            "source": self.source,
            "added": list(self.added),
            "unexplained": bool(self.unexplained),
            "signature": [d.to_json() for d in self.signature],
            "before": stage(self.before),
            "after": stage(self.after),
            "test": {
                "statistic": "score (Lagrange multiplier) test through the factor graph, chi-square under "
                             "the null; Bonferroni over the candidates of a round",
                "alpha": self.options.alpha,
                "identifiable_information_ratio": self.options.identifiable,
                "driver_tests": "the same score test of generic drivers placed as a bias on each sensor axis",
                "n_candidates_last_round": sum(1 for c in last.candidates if not c.skipped) if last else 0,
                "n_driver_tests": len(last.drivers) if last else 0,
            },
            "rounds": [r.to_json() for r in self.rounds],
            "context": self.context,
            "seconds": self.seconds,
        })


def _finite(obj):
    """``obj`` with every non-finite float replaced by None (JSON has no NaN or infinity)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, (float, np.floating)) and not np.isfinite(obj):
        return None
    return obj

