"""The verdict of a calibration, in words and in the exit code: converged, solvers agree, residuals consistent.

cli.md: every command that calibrates decides, and prints in words, whether each solver converged,
whether the solvers agree within their tolerance, and whether the residuals are consistent with the
noise model; a failed verdict exits 3 with every file still written.

The residual test is the batch fit's chi-square per degree of freedom,
``2 F / (3 K_gravity + 3 M_encoder)``, with ``F`` the solver's final cost (half the sum of squared
whitened residuals, priors included): the measurements are the gravity and encoder factors, and the
rotation factors and priors bring as many equations as the attitudes and the calibration have
unknowns.  It is near 1 when the noise model fits (0.66-0.71 on the simulated navigation-grade
subranges: the simulator's two encoders read no noise about the direction perpendicular to both axes,
and the model floors that component of every static reading at a quarter of the declared encoder noise,
docs/model.md, so a third of the encoder components carry almost no chi-square), and it grows with what the model lacks (3.8 on the measured MPU-6050 session, 2.1-2.9
on the measured Xsens session cut short; both lack the gyro g-sensitivity the diagnosis finds).  Above
:data:`RESIDUAL_CHI2_LIMIT` the reported sigmas are too small by more than ``sqrt(2)``: the verdict
fails.  Far below 1 the noise model is overstated and the sigmas are conservative: said, not failed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from graph_calib.model.residual_list import MEASUREMENT_KINDS

#: Largest chi-square per degree of freedom of a fit that passes (sigmas optimistic by at most sqrt(2)).
RESIDUAL_CHI2_LIMIT = 2.0
#: Below this the noise model is said to be overstated (sigmas conservative); the verdict still passes.
RESIDUAL_CHI2_LOW = 0.25


def fit_chi2_per_dof(block):
    """Chi-square per degree of freedom of a fit from a result's ``residuals`` block (None if unknown)."""
    counts = block.get("counts") or {}
    dof = 3 * sum(int(counts.get(k, 0)) for k in MEASUREMENT_KINDS)
    cost = block.get("final_cost")
    if cost is None or dof <= 0:
        return None
    return 2.0 * float(cost) / dof


@dataclass(frozen=True)
class Verdict:
    """Whether a calibration can be trusted, and why not.

    Attributes
    ----------
    converged : mapping of str to bool
        Per solver.
    agree : bool or None
        Whether the solvers agree within the comparison's tolerance (None with one solver).
    max_difference_sigma : float or None
        The comparison's largest difference, in sigmas.
    fit_chi2 : mapping of str to float
        Per solver, the fit's chi-square per degree of freedom.
    passed : bool
    problems : tuple of str
        What failed, in words (empty when passed).
    notes : tuple of str
        What the user should know although it did not fail the verdict.
    """

    converged: Mapping[str, bool]
    agree: bool | None
    max_difference_sigma: float | None
    fit_chi2: Mapping[str, float]
    passed: bool
    problems: tuple = ()
    notes: tuple = ()

    def text(self):
        """The verdict line, in words."""
        conv = ("converged" if all(self.converged.values())
                else "NOT CONVERGED: " + ", ".join(s for s, c in self.converged.items() if not c))
        if self.agree is None:
            agree = "one solver"
        elif self.agree:
            agree = f"solvers agree (max {self.max_difference_sigma:.2g} sigma)"
        else:
            agree = f"SOLVERS DISAGREE (max {self.max_difference_sigma:.3g} sigma)"
        chi = ", ".join(f"{s} {v:.2f}" for s, v in self.fit_chi2.items())
        bad = [s for s, v in self.fit_chi2.items() if v > RESIDUAL_CHI2_LIMIT]
        resid = (f"RESIDUALS INCONSISTENT WITH THE NOISE MODEL (chi2/dof {chi} > {RESIDUAL_CHI2_LIMIT:g})" if bad
                 else f"residuals consistent (chi2/dof {chi})")
        head = "verdict: pass" if self.passed else "verdict: FAIL"
        return f"{head}: {conv}; {agree}; {resid}" + "".join(f"; note: {n}" for n in self.notes)

    def to_json(self):
        return {"passed": bool(self.passed), "converged": {k: bool(v) for k, v in self.converged.items()},
                "agree": self.agree, "max_difference_in_sigma": self.max_difference_sigma,
                "fit_chi2_per_dof": dict(self.fit_chi2), "residual_chi2_limit": RESIDUAL_CHI2_LIMIT,
                "problems": list(self.problems), "notes": list(self.notes), "text": self.text()}


def verdict_of(results, comparison=None):
    """The :class:`Verdict` of solver results (``{solver: Result}``) and their comparison (``comparison.json``)."""
    converged = {s: bool(r.residuals.get("converged", False)) for s, r in results.items()}
    fit = {}
    for s, r in results.items():
        v = fit_chi2_per_dof(r.residuals)
        if v is not None:
            fit[s] = v
    problems, notes = [], []
    for s, c in converged.items():
        if not c:
            problems.append(f"{s} did not converge (its iteration limit ended it)")
    agree = maxdiff = None
    if comparison is not None:
        sm = comparison["summary"]
        agree, maxdiff = bool(sm["agree"]), float(sm["max_abs_difference_in_sigma"])
        if not agree:
            problems.append(f"the solvers disagree: max |difference| {maxdiff:.3g} sigma, sigma ratio range "
                            f"{sm['sigma_ratio_range']}")
    for s, v in fit.items():
        if v > RESIDUAL_CHI2_LIMIT:
            problems.append(f"{s}: residuals inconsistent with the noise model, chi2/dof {v:.2f} > "
                            f"{RESIDUAL_CHI2_LIMIT:g}: the model lacks an effect or the noise is larger than "
                            f"assumed (wrong grade?); sigmas are optimistic by about {v ** 0.5:.1f}x")
        elif v < RESIDUAL_CHI2_LOW:
            notes.append(f"{s}: residuals well inside the noise model (chi2/dof {v:.2f}): sigmas conservative")
    return Verdict(converged=converged, agree=agree, max_difference_sigma=maxdiff, fit_chi2=fit,
                   passed=not problems, problems=tuple(problems), notes=tuple(notes))


__all__ = ["Verdict", "verdict_of", "fit_chi2_per_dof", "RESIDUAL_CHI2_LIMIT", "RESIDUAL_CHI2_LOW"]
