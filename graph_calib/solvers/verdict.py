"""The verdict of a calibration, in words and in the exit code: converged, solvers agree, residuals consistent.

cli.md: every command that calibrates decides, and prints in words, whether each solver converged,
whether the solvers agree within their tolerance, and whether the residuals are consistent with the
noise model; a failed verdict exits 3 with every file still written.

The residual test is made per measurement kind (rotation, gravity, encoder) on the result's
``residuals.kinds`` (data-format.md): ``chi2 / redundancy``, whose expectation is 1 when the noise model
is right (:mod:`graph_calib.model.redundancy`).  With redundancy ``nu`` the statistic ``chi2`` is
chi-square with ``nu`` degrees of freedom, so a kind fails when its ``chi2 / nu`` lies outside the
two-sided :data:`RESIDUAL_ALPHA` quantiles ``chi2_{alpha/2}(nu) / nu .. chi2_{1-alpha/2}(nu) / nu``:
above, the kind's residuals are larger than its noise (the model lacks an effect, or the noise is
larger than identified; the sigmas are optimistic); below, the noise model overstates them (the sigmas
are pessimistic).  The limits narrow as the redundancy grows (about ``1 +- 3.3 sqrt(2 / nu)``).

With variance components (:mod:`graph_calib.solvers.variance`) each component's ``chi2 / redundancy`` is
brought to 1 by a variance factor (the rotation kind shares the gyro's with the table readings' gyro term, so its
own scatters about 1 within the limits above); the factor itself is then the test: a kind whose factor lies
outside ``1 / VARIANCE_FACTOR_LIMIT .. VARIANCE_FACTOR_LIMIT`` of the noise identified from the record
fails, naming the kind and the factor (its residuals are that many times, in variance, what the
identified noise explains).  A kind whose sensor's noise was the grade's (nothing identified) is not
judged by its factor: the grade's table value is no measurement.  One case of it fails all the same:
table readings whose static dwells do not scatter (below the identification floor: noise-free
readings).  Their residuals are then the gyro's angle random walk from the keyframe to each reading,
correlated from reading to reading, which the encoder factors take as independent; no variance factor
makes that right (docs/model.md measures the sigmas 1.4 times optimistic at the factor the residuals
ask for), and the verdict says so in words.

Variance components that did not settle within their solves (``residuals.variance_iteration.converged`` false) get
a note with each kind's last ``chi2 / redundancy``: the final solve's per-kind test still judges the result.

A record without a table whose rests scatter beyond white noise while no sway term models it (the result's
``noise.identified.sway_seen_mps2``) gets a note naming the sway and ``--sway-sigma estimate``: a short record's
residual test does not see it (docs/model.md, "A hand").  One whose gyros sit at their largest output in runs that
no segment boundary follows (``noise.identified.gyro_flat_tops``: a saturated gyro the record was not cut for) gets a
note naming the axes and ``--gyro-range-dps`` (docs/model.md, "A saturated gyro").

Without variance factors (``residuals.variance_components`` false: a campaign's tasks) a kind below
its lower limit is a note, not a failure: the kinds' own approximations keep a right model's rotation
and encoder kinds below 1 (docs/model.md).  A result without per-kind redundancies (a solver that does
not give them) is judged as before, by its chi-square per measurement component against
:data:`RESIDUAL_CHI2_LIMIT`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from graph_calib.constants import RAD_TO_ARCSEC
from graph_calib.model.options import SATURATION_SEEN_KEY, SWAY_SEEN_KEY
from graph_calib.model.residual_list import MEASUREMENT_KINDS
from graph_calib.records.saturation import flat_top_text
from graph_calib.solvers.results import PRIOR_DOMINATED_RATIO

#: Largest chi-square per measurement component of a result without redundancies (the old statistic).
RESIDUAL_CHI2_LIMIT = 2.0
#: Below this the old statistic says the noise model is overstated (sigmas conservative).
RESIDUAL_CHI2_LOW = 0.25
#: Two-sided probability of a right model's kind falling outside its limits.
RESIDUAL_ALPHA = 1e-3
#: A kind's variance factor beyond this (or below its inverse) fails the verdict.
VARIANCE_FACTOR_LIMIT = 4.0
#: A kind's variance factor within the limit but outside this band gets a note naming the kind and what the factor says
#: (issue #21's bar for the measured sessions: within it, or the verdict says which kind does not fit and why).
NOTE_FACTOR_BAND = (0.8, 1.25)
#: The words of a staged solve's problem (:mod:`graph_calib.solvers.staged`), which the verdict line repeats.
STAGED_WORDS = "the gyro model does not fit"
#: The share of a result's elements held by their priors from which the verdict says so.
PRIOR_HELD_SHARE = 0.5
#: The words of that note (the campaign's summary and report pick it out by them).
PRIOR_HELD_WORDS = "are held by their priors"
#: Least redundancy of a kind the residual test judges (one degree of freedom).
MIN_JUDGED_REDUNDANCY = 1.0
#: The part of the gravity kind's figures the verdict judges where the moving keyframes' are apart (data-format.md).
STATIC_PART = "static"
#: The measurement kinds the verdict judges, and the sensor whose noise each is weighted by.
JUDGED_KINDS = {"rotation": "gyro", "gravity": "accel", "encoder": "encoder", "still": "gyro", "turn": "protocol"}
#: What a kind's residuals measure, where its name does not say (the verdict's words).
KIND_WORDS = {"still": "still (the rests' gyro integrals against the Earth's turn)",
              "turn": "guided-turn (the Ferraris protocol's full turns: closing, flat)"}
#: A sensor's name in the verdict's words.
SENSOR_WORDS = {"accel": "accelerometer", "encoder": "table-reading", "protocol": "guided-turn protocol"}
#: Kinds whose sigma is a declared bound of a protocol (no noise identified): their residuals well below it are a
#: note, in these words.
DECLARED_SPREAD_KINDS = {"turn": "the guided turns close and stay flat better than their declared spread: what they "
                                 "inform is weighted conservatively (--guided-turns DEG declares a tighter spread)"}
#: What beside a lacking effect makes a kind's residuals too large, where the sensor's noise is not all of it.
KIND_CAUSES = {"still": "the unit turned while it rested (declare the rests still only where it sits on a surface), "
                        "or the gyro noise is larger than assumed",
               "turn": "the full turns do not close or tilt more than a turn pressed against a guide on a level surface "
                       "does (--guided-turns DEG declares their spread, --guided-turns off takes them for motion)"}


def kind_limits(redundancy, *, alpha=RESIDUAL_ALPHA):
    """``(low, high)`` limits of ``chi2 / redundancy`` for a kind of that redundancy (module doc)."""
    from scipy.special import gammaincinv    # scipy.stats is 0.3 s of every command's start: only the quantile here

    nu = float(redundancy)
    if not nu > 0:
        return 0.0, float("inf")
    # the chi-square quantile: chi2.ppf(p, nu) = 2 gammaincinv(nu / 2, p)
    return (float(2.0 * gammaincinv(0.5 * nu, 0.5 * alpha) / nu),
            float(2.0 * gammaincinv(0.5 * nu, 1.0 - 0.5 * alpha) / nu))


def judged_figures(kinds, kind):
    """The figures of ``kinds[kind]`` (a result's ``residuals.kinds``) that the residual test judges: the kind's own,
    or for gravity with the moving keyframes apart its static keyframes' (:data:`STATIC_PART`: the moving ones'
    sigma is their own, a guess or estimated, and no claim of the noise model;
    :func:`graph_calib.model.redundancy.static_gravity`)."""
    k = kinds.get(kind) or {}
    static = k.get(STATIC_PART) if kind == "gravity" else None
    return static if static and static.get("chi2_per_redundancy") is not None else k


def _overstated(kind, sensor, noise):
    """What an overstated noise of ``kind`` is: the sensor's, or with a sway term the gravity factors' noise and it."""
    sway = noise.get("sway_mps2")
    if kind == "gravity" and sway:
        return (f"{sensor} noise or the sway term ({float(sway):.2g} m/s^2: rests that sway less than their specific "
                "force's scatter says, or no hand at all: drop --sway-sigma)")
    return f"{sensor} noise"


def judge_kinds(result):
    """``(figures, problems, notes)`` of one result's per-kind residual test.

    ``figures``: ``{kind: {chi2_per_redundancy, redundancy, low, high, variance_factor}}`` of the kinds
    judged (empty when the result gives no redundancies).
    """
    kinds = (result.residuals or {}).get("kinds") or {}
    scaled = bool((result.residuals or {}).get("variance_components", True))
    noise = (result.extra or {}).get("noise") or {}
    source = noise.get("source") or {}
    quiet = ((noise.get("identified") or {}).get("encoder") or {}).get("below_rad")
    figures, problems, notes = {}, [], []
    for kind, sensor in JUDGED_KINDS.items():
        k = kinds.get(kind)
        if not k or k.get("redundancy") is None or k.get("chi2_per_redundancy") is None:
            continue
        vf = float(k.get("variance_factor", 1.0))
        judged = judged_figures(kinds, kind)
        v, nu = float(judged["chi2_per_redundancy"]), float(judged["redundancy"])
        if nu < MIN_JUDGED_REDUNDANCY:
            # the attitudes and the calibration absorb the kind's residuals: nothing left to test them by (and the
            # chi-square quantile of a vanishing redundancy is no number)
            notes.append(f"{kind}: redundancy {nu:.2g}, too little to test its residuals")
            continue
        lo, hi = kind_limits(nu)
        figures[kind] = {"chi2_per_redundancy": v, "redundancy": nu, "low": lo, "high": hi, "variance_factor": vf}
        part = " (static keyframes)" if judged is not k else ""
        what = f"{kind}{part} chi2/redundancy {v:.3g} (redundancy {nu:.1f})"
        if kind == "encoder" and quiet and source.get("encoder") == "grade":
            problems.append(_quiet_readings_text(what, quiet))
            continue
        if v > hi:
            cause = KIND_CAUSES.get(kind, f"the {sensor} noise is larger than assumed")
            problems.append(f"{what} > {hi:.3g}: the {KIND_WORDS.get(kind, kind)} residuals are larger than their "
                            f"noise model; the model lacks an effect or {cause}; sigmas optimistic by about "
                            f"{v ** 0.5:.2g}x")
        elif v < lo and kind in DECLARED_SPREAD_KINDS:
            # a declared spread is a bound on the protocol, not a noise density: turns that keep it better are news,
            # not a misfit
            notes.append(f"{what} < {lo:.3g}: {DECLARED_SPREAD_KINDS[kind]}")
        elif v < lo:
            text = (f"{what} < {lo:.3g}: the {kind} residuals are smaller than their noise model; the "
                    f"{_overstated(kind, sensor, noise)} is overstated; "
                    + (f"sigmas pessimistic by about {v ** -0.5:.2g}x" if v > 0 else
                       "the residuals are zero (no noise at all)"))
            # without variance factors the kinds' approximations (module doc) keep a right model below 1: said
            (problems if scaled else notes).append(text + ("" if scaled else " (no variance components estimated)"))
        if vf != 1.0:
            if source.get(sensor) == "grade":
                notes.append(f"{kind}: variance factor {vf:.3g} on the {sensor} noise of the grade (none identified)")
            elif vf > VARIANCE_FACTOR_LIMIT and kind in DECLARED_SPREAD_KINDS:
                problems.append(f"{kind} residuals need a variance factor {vf:.3g} > {VARIANCE_FACTOR_LIMIT:g} on "
                                f"their declared noise: {KIND_CAUSES[kind]}")
            elif vf > VARIANCE_FACTOR_LIMIT:
                problems.append(f"{kind} residuals need a variance factor {vf:.3g} > {VARIANCE_FACTOR_LIMIT:g} on "
                                f"the {source.get(sensor, 'assumed')} {sensor} noise: the model lacks an effect "
                                f"the {kind} measurements see")
            elif vf < 1.0 / VARIANCE_FACTOR_LIMIT:
                problems.append(f"{kind} residuals need a variance factor {vf:.3g} < 1/{VARIANCE_FACTOR_LIMIT:g} on "
                                f"the {source.get(sensor, 'assumed')} {sensor} noise: the "
                                f"{_overstated(kind, sensor, noise)} is overstated")
            elif not NOTE_FACTOR_BAND[0] <= vf <= NOTE_FACTOR_BAND[1]:
                notes.append(_factor_note(kind, sensor, vf, source.get(sensor, "assumed")))
    for kind in ((result.residuals or {}).get("variance_iteration") or {}).get("held") or ():
        if kind in figures:
            f = figures[kind]
            notes.append(f"{kind}: chi2/redundancy {f['chi2_per_redundancy']:.2g} over a redundancy of "
                         f"{f['redundancy']:.0f}, too few degrees of freedom to lower its variance factor below 1: "
                         "the sigmas it governs may be conservative")
    unsettled = _unsettled_text((result.residuals or {}).get("variance_iteration"))
    if unsettled:
        notes.append(unsettled)
    seen = (noise.get("identified") or {}).get(SWAY_SEEN_KEY)
    if seen and not noise.get("sway_mps2"):
        notes.append(_sway_text(seen))
    tops = (noise.get("identified") or {}).get(SATURATION_SEEN_KEY)
    if tops:
        notes.append(_flat_top_text(tops))
    turns = noise.get("guided_turns")
    if turns:
        notes.append(f"{turns['count']} full turn(s) about the vertical between two rests on one face taken as a "
                     f"Ferraris session's guided turns (closing, flat; {math.degrees(turns['sigma_rad']):.2g} deg): "
                     "--guided-turns off takes them for motion")
    staged = _staged_text((result.extra or {}).get("staged"))
    if staged:
        problems.append(staged)
    return figures, problems, notes


def _factor_note(kind, sensor, factor, source):
    """The note of a kind whose variance factor lies within the limit but outside :data:`NOTE_FACTOR_BAND`."""
    what = KIND_WORDS.get(kind, kind)
    sensor = SENSOR_WORDS.get(sensor, sensor)
    if kind in DECLARED_SPREAD_KINDS:
        return (f"{kind}: variance factor {factor:.2g}: the {what} residuals scatter {factor:.2g} times, in variance, "
                f"their declared spread (a hand's turns closing and lying flat less well than declared); the sigmas "
                f"it governs are scaled by {factor ** 0.5:.2g}, as the residuals ask")
    if factor > 1.0:
        cause = (f"a small effect the model lacks (below the structure tests' thresholds), or {sensor} noise beyond "
                 "white over a keyframe (a bias instability)")
    else:
        cause = (f"the {sensor} noise over a keyframe is less than the rests' Allan fit gives (noise that is not white "
                 "between the samples and the keyframes, or a sway or vibration at rest)")
    return (f"{kind}: variance factor {factor:.2g}: the {what} residuals scatter {factor:.2g} times, in variance, what "
            f"the {source} {sensor} noise explains: {cause}; the sigmas it governs are scaled by "
            f"{factor ** 0.5:.2g}, as the residuals ask")


def _unsettled_text(iteration):
    """The verdict's note on variance components that did not settle (``residuals.variance_iteration``; None when
    they did or were not estimated)."""
    if not iteration or iteration.get("converged", True):
        return None
    last = ", ".join(f"{k} {float(v):.3g}" for k, v in (iteration.get("last") or {}).items())
    bound = list(iteration.get("at_bound") or ())
    why = (f" ({', '.join(bound)} at the bound of {'its' if len(bound) == 1 else 'their'} variance factor, the "
           f"residuals asking for more)" if bound else "")
    return (f"the variance components did not settle in {iteration.get('solves')} solves{why} (chi2/redundancy at the "
            f"last: {last}): the factors are the last rescale's, and the sigmas follow them only as far as the "
            f"residual test of the final solve above shows")


def _staged_text(block):
    """The verdict's words on a result's ``staged`` block (:mod:`graph_calib.solvers.staged`; None: not staged)."""
    if not block or not block.get("staged"):
        return None
    return (f"{STAGED_WORDS}: its misfit (the joint solve's variance factors rotation "
            f"{block['rotation_variance_factor']:.3g}, gravity {block.get('gravity_variance_factor', 1.0):.3g}) pulls "
            f"the accelerometer calibration away from what gravity alone gives (statistic "
            f"{block['statistic']:.3g} > {block['threshold']:.3g} over {block['dof']} elements): the accelerometer is "
            f"calibrated from gravity alone and the gyro given it (a staged solve); the gyro model lacks an effect")


def _sway_text(seen_mps2):
    """The verdict's note on a sway the rests show and no sway term models (docs/model.md, "A hand")."""
    return (f"gravity: the rests' keyframe means scatter {seen_mps2:.2g} m/s^2 beyond the accelerometer's white noise "
            f"(a hand's sway, or a bias instability), which the gravity factors take for white noise: the sigmas of "
            f"what the rests inform may be optimistic (--sway-sigma estimate models it)")


def _flat_top_text(tops):
    """The verdict's note on gyro outputs that sit at their extreme in runs the record was not cut for."""
    return (f"rotation: the gyros sit at their largest output {flat_top_text(tops)} and the record is not cut after "
            "them: a saturated gyro loses the angle beyond its range, which the rotation factors take for an error of "
            "the model (--gyro-range-dps with the gyros' range, on calibrate, diagnose or import, cuts the record after "
            "each saturated turn; docs/model.md, \"A saturated gyro\")")


def _quiet_readings_text(what, floor_rad):
    """The verdict's words for table readings whose static dwells show no noise (docs/model.md)."""
    return (f"{what}: the table readings do not scatter (their static dwells show less than "
            f"{floor_rad * RAD_TO_ARCSEC:.2g} arcsec), so their noise is not identified and the grade's is no "
            f"measurement of it; the encoder factors' residuals are then the gyro's angle random walk from the "
            f"keyframe to each reading, correlated from reading to reading, which the model takes as independent: "
            f"no variance factor makes that right, and the sigmas of what the readings inform are not reliable "
            f"(declare the readings' noise, encoder_noise, if it is known)")


def fit_chi2_per_redundancy(block):
    """Chi-square over redundancy of the measurement kinds together (None without redundancies)."""
    kinds = (block or {}).get("kinds") or {}
    c = r = 0.0
    for kind in JUDGED_KINDS:
        k = judged_figures(kinds, kind)
        if k.get("redundancy") is not None and k.get("chi2") is not None:
            c += float(k["chi2"])
            r += float(k["redundancy"])
    return c / r if r > 0 else None


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
        Per solver, the measurement kinds' chi-square over their redundancy together (the old chi-square
        per component for a result without redundancies).
    kinds : mapping of str to dict
        Per solver, each judged kind's figures and limits (:func:`judge_kinds`).
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
    kinds: Mapping[str, dict] = field(default_factory=dict)
    structure: tuple = ()

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
        resid = self._residual_text()
        if any(STAGED_WORDS in p for p in self.problems):
            resid += ("; THE GYRO MODEL DOES NOT FIT: its misfit pulled the accelerometer calibration, which is "
                      "calibrated from gravity alone, the gyro given it (staged solve)")
        head = "verdict: pass" if self.passed else "verdict: FAIL"
        return f"{head}: {conv}; {agree}; {resid}" + "".join(f"; note: {n}" for n in self.notes)

    def _residual_text(self):
        carried = [t for t in self.structure if t["significant"]]
        if carried:
            return ("RESIDUALS CARRY AN EFFECT THE MODEL LACKS: " + ", ".join(
                f"{t['effect']} (score {t['statistic']:.3g} > {t['threshold']:.3g})" for t in carried))
        if self.kinds:
            first = next(iter(self.kinds.values()))
            figs = ", ".join(f"{k} {f['chi2_per_redundancy']:.2f}" + (f" (variance factor {f['variance_factor']:.2g})"
                                                                      if f["variance_factor"] != 1.0 else "")
                             for k, f in first.items())
            bad = [k for k in JUDGED_KINDS if any(p.startswith(f"{k} ") or f": {k} " in p for p in self.problems)]
            if bad:
                return f"RESIDUALS INCONSISTENT WITH THE NOISE MODEL: {', '.join(bad)} (chi2/redundancy {figs})"
            return f"residuals consistent (chi2/redundancy {figs})"
        chi = ", ".join(f"{s} {v:.2f}" for s, v in self.fit_chi2.items())
        bad = [s for s, v in self.fit_chi2.items() if v > RESIDUAL_CHI2_LIMIT]
        return (f"RESIDUALS INCONSISTENT WITH THE NOISE MODEL (chi2/dof {chi} > {RESIDUAL_CHI2_LIMIT:g})" if bad
                else f"residuals consistent (chi2/dof {chi})")

    def to_json(self):
        return {"passed": bool(self.passed), "converged": {k: bool(v) for k, v in self.converged.items()},
                "agree": self.agree, "max_difference_in_sigma": self.max_difference_sigma,
                "fit_chi2_per_dof": dict(self.fit_chi2), "residual_chi2_limit": RESIDUAL_CHI2_LIMIT,
                "kinds": {s: dict(k) for s, k in self.kinds.items()}, "residual_alpha": RESIDUAL_ALPHA,
                "structure": [dict(t) for t in self.structure],
                "variance_factor_limit": VARIANCE_FACTOR_LIMIT,
                "problems": list(self.problems), "notes": list(self.notes), "text": self.text()}


def _cost_words(results, comparison):
    """Which of the two compared solvers stopped at the lower batch cost (``residuals.final_cost``), in words; ""
    when either cost is missing or they are equal to 1e-9 relative."""
    names = list(comparison.get("solvers") or [])[:2] or list(results)[:2]
    costs = {n: results[n].residuals.get("final_cost") for n in names if n in results}
    if len(costs) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in costs.values()):
        return ""
    (lo, c_lo), (hi, c_hi) = sorted(costs.items(), key=lambda kv: kv[1])
    if c_hi - c_lo <= 1e-9 * max(abs(c_lo), 1.0):
        return ""
    return (f"; {lo} stopped at the lower batch cost ({c_lo:.6g} against {c_hi:.6g} for {hi}): the two stopped "
            "in different places of a flat valley or in two minima, and the lower is the better fit")


def verdict_of(results, comparison=None, *, structure=()):
    """The :class:`Verdict` of solver results (``{solver: Result}``) and their comparison (``comparison.json``).

    ``structure``: the score tests of the candidates the model lacks at the solution
    (:func:`graph_calib.diagnosis.structure.structure_tests`, each with ``to_json``, or its dicts); a
    significant one fails the residual part, named.
    """
    structure = tuple(t if isinstance(t, dict) else t.to_json() for t in structure)
    converged = {s: bool(r.residuals.get("converged", False)) for s, r in results.items()}
    fit, kinds = {}, {}
    problems, notes = [], []
    for s, c in converged.items():
        if not c:
            problems.append(f"{s} did not converge (its iteration limit ended it)")
    agree = maxdiff = None
    if comparison is not None:
        sm = comparison["summary"]
        agree, maxdiff = bool(sm["agree"]), float(sm["max_abs_difference_in_sigma"])
        if not agree:
            rr = sm.get("sigma_ratio_range")
            rr = f"{float(rr[0]):.3f}..{float(rr[1]):.3f}" if rr is not None and len(rr) == 2 else f"{rr}"
            problems.append(f"the solvers disagree: max |difference| {maxdiff:.3g} sigma, sigma ratio range {rr}"
                            + _cost_words(results, comparison))
    for s, r in results.items():
        held = (r.extra or {}).get("prior_dominated") or {}
        if r.values and len(held) >= PRIOR_HELD_SHARE * len(r.values):
            notes.append(f"{s}: {len(held)} of {len(r.values)} elements {PRIOR_HELD_WORDS} (sigma above "
                         f"{PRIOR_DOMINATED_RATIO:g} of the prior's): the record informs little of this model, and "
                         "their values and sigmas are the priors' (prior_dominated in the result)")
        figures, kp, kn = judge_kinds(r)
        if figures:
            kinds[s] = figures
            fit[s] = fit_chi2_per_redundancy(r.residuals)
            problems.extend(f"{s}: {p}" for p in kp)
            notes.extend(f"{s}: {n}" for n in kn)
            continue
        v = fit_chi2_per_dof(r.residuals)
        if v is None:
            continue
        fit[s] = v
        if v > RESIDUAL_CHI2_LIMIT:
            problems.append(f"{s}: residuals inconsistent with the noise model, chi2/dof {v:.2f} > "
                            f"{RESIDUAL_CHI2_LIMIT:g}: the model lacks an effect or the noise is larger than "
                            f"assumed (wrong grade?); sigmas are optimistic by about {v ** 0.5:.1f}x")
        elif v < RESIDUAL_CHI2_LOW:
            notes.append(f"{s}: residuals well inside the noise model (chi2/dof {v:.2f}): sigmas conservative")
    for t in structure:
        if t["significant"]:
            problems.append(f"the residuals carry {t['effect']}: score statistic {t['statistic']:.3g} > threshold "
                            f"{t['threshold']:.3g} ({t['dof']} dof): the model lacks it or an effect that shares its "
                            "signature")
    constant = [s for s, r in results.items() if _constant_temperature(r)]
    if problems and constant:
        T = results[constant[0]].temperature_range_degC[0]
        notes.append(f"the record's temperature does not change ({T:g} degC over the whole record): no temperature "
                     "effect is estimated, and a drift the sensors show while warming up is one of time to the model "
                     "and its tests (a constant temperature assumed at import, --temperature, hides a real warm-up)")
    return Verdict(converged=converged, agree=agree, max_difference_sigma=maxdiff, fit_chi2=fit,
                   passed=not problems, problems=tuple(problems), notes=tuple(notes), kinds=kinds,
                   structure=structure)


def _constant_temperature(result):
    """Whether a result's record has one temperature throughout (its ``temperature_range_degC`` ends equal)."""
    rng = getattr(result, "temperature_range_degC", None)
    return rng is not None and len(rng) == 2 and float(rng[1]) - float(rng[0]) == 0.0


__all__ = ["Verdict", "verdict_of", "judge_kinds", "judged_figures", "kind_limits", "fit_chi2_per_dof", "fit_chi2_per_redundancy",
           "RESIDUAL_CHI2_LIMIT", "RESIDUAL_CHI2_LOW", "RESIDUAL_ALPHA", "VARIANCE_FACTOR_LIMIT", "NOTE_FACTOR_BAND", "JUDGED_KINDS"]
