"""The next test after an ambiguous diagnosis: the protocol that best separates two
candidate models, `jaxcable.design_discriminating_test`."""

import dataclasses
import math
import typing

import jax
import jax.numpy as jnp
import numpy as np

from .._cable import Cable
from .._drive import simulate_force_history, simulate_rate_test
from .._fit import FitResult
from . import design as _d
from .methods import TestDesign


@dataclasses.dataclass(frozen=True)
class DiscriminatingTest(_d.DesignedProtocol):
    """The outcome of [`jaxcable.design_discriminating_test`][].

    **Fields:**

    - `protocol`, `cable`, `document`: the designed test, the cable at its
        crosshead speed and the protocol file, as [`jaxcable.DesignedTest`][]'s.
    - `candidates`: the two candidates' names `(a, b)`.
    - `parameters`: each candidate's number of fitted parameters.
    - `bic_now`: BIC(b) - BIC(a) on the data so far (a diagnosis's training
        samples; NaN when not known): > 0 favours a.
    - `separation`: `(T_ab, T_ba)` of the designed test: T_ab the lack of fit,
        in noise units (a sum of squared residuals over sigma^2), that b keeps
        when a is true and b is refitted to the new test and the old data
        together (linearised), T_ba the converse.
    - `separation_standard`: the same for Park's 10-cycle protocol of the same
        duration and largest force.
    - `samples`: samples of the designed test.
    - `samples_before`: samples of the data so far (those `bic_now` counts).
    - `duration_s`: its simulated duration, s.
    - `noise_m`: the elongation noise the separations are in units of, m.
    """

    candidates: tuple[str, str]
    parameters: tuple[int, int]
    bic_now: float
    separation: tuple[float, float]
    separation_standard: tuple[float, float]
    samples: int
    samples_before: int
    duration_s: float
    noise_m: float

    def expected_delta_bic(self, standard: bool = False) -> tuple[float, float]:
        """The expected BIC(wrong) - BIC(true) after the test: `(if a is true, if b
        is true)`. The BIC difference so far (NaN counts as 0), plus the
        separation (a chi-square's excess: the wrong model's sum of squares grows
        by T sigma^2), plus the growth of the parameters' penalty k ln n with the
        new samples, (k_wrong - k_true) ln((n_before + n_new) / n_before).

        Optimistic: it takes each fit's parameters for the truth and the wrong
        candidate's refit as linear, so it ranks tests better than it predicts
        the BIC difference a run will show (benchmarks/README.md has both)."""
        t_ab, t_ba = self.separation_standard if standard else self.separation
        now = 0.0 if math.isnan(self.bic_now) else self.bic_now
        ka, kb = self.parameters
        before = max(self.samples_before, 1)
        grow = math.log((before + self.samples) / before)
        return (now + t_ab + (kb - ka) * grow, -now + t_ba + (ka - kb) * grow)

    def summary(self) -> str:
        """What the test is, how well it is expected to separate the two
        candidates, and why."""
        segs = self.document["segments"]
        a, b = self.candidates
        lines = [
            f"discriminating test: {a} against {b}",
            f"  {self.document['rate_mm_per_min']:.3g} mm/min, {len(segs)} segments, "
            f"{self.duration_s:.0f} s, {self.samples} samples",
        ]
        for s in segs:
            lines.append("  " + ", ".join(f"{k} {v:.4g}" for k, v in s.items()))
        designed = self.expected_delta_bic()
        standard = self.expected_delta_bic(standard=True)
        lines += [
            "",
            f"{'expected BIC(wrong) - BIC(true)':<34} {'designed':>9} {'standard':>9}",
            f"{'  if ' + a + ' is true':<34} {designed[0]:>9.1f} {standard[0]:>9.1f}",
            f"{'  if ' + b + ' is true':<34} {designed[1]:>9.1f} {standard[1]:>9.1f}",
            "",
            self.why(),
        ]
        return "\n".join(lines)

    def why(self) -> str:
        """One paragraph: the criterion and the expected separation."""
        a, b = self.candidates
        designed = min(self.expected_delta_bic())
        standard = min(self.expected_delta_bic(standard=True))
        now = "unknown" if math.isnan(self.bic_now) else f"{self.bic_now:+.1f}"
        verdict = (
            "enough to separate them (>= 10, very strong evidence) whichever is true"
            if designed >= 10
            else "not enough for very strong evidence (10): a longer test, a larger "
            "force or a second test is needed"
        )
        if math.isnan(self.bic_now) or abs(self.bic_now) <= 10:
            so_far = "explain the data so far about equally"
        else:
            ahead = a if self.bic_now > 0 else b
            so_far = f"are not equal on the data so far ({ahead} is ahead)"
        return (
            f"The two candidates {a} and {b} {so_far} (BIC({b}) - BIC({a}) = "
            f"{now}). The test maximises the smaller of the two lack-of-fit sums "
            "(T-optimal: the wrong candidate refitted to what the true one "
            "predicts, old data included, linearised), so that it "
            "separates them whichever is true: the expected BIC difference in "
            f"favour of the true one is at least {designed:.1f} ({verdict}); Park's "
            f"10-cycle protocol of the same duration: {standard:.1f}."
        )


def _response(knowledge: _d.Knowledge, cable: Cable, time, force):
    """The elongations (m) of a force history and their Jacobian in theta."""

    def elongation(theta):
        traj = simulate_force_history(
            knowledge.with_theta(theta), cable, time, force, method=_d.QUIET
        )
        return traj.elongation, traj.elongation

    jac, value = jax.jacfwd(elongation, has_aux=True)(jnp.asarray(knowledge.theta))
    return value, jac


def _lack_of_fit(difference, jac, precision, sigma):
    """min over d of |difference - jac d|^2 / sigma^2 + d^T precision d: what a
    candidate cannot absorb of another's prediction by moving its parameters, held
    by what the old data (and the prior) know of them."""
    g = jac.T @ difference / sigma**2
    a = jac.T @ jac / sigma**2 + precision
    return difference @ difference / sigma**2 - g @ jnp.linalg.solve(a, g)


def separations(
    first: _d.Knowledge, second: _d.Knowledge, cable: Cable, time, force, sigma
):
    """`(T_ab, T_ba)` of one force history (s, N): see `DiscriminatingTest`."""
    ea, ja = _response(first, cable, time, force)
    eb, jb = _response(second, cable, time, force)
    d = ea - eb
    t_ab = _lack_of_fit(d, jb, jnp.asarray(second.precision()), sigma)
    t_ba = _lack_of_fit(-d, ja, jnp.asarray(first.precision()), sigma)
    return t_ab, t_ba


def _bic(fit: FitResult) -> float:
    """The diagnosis's BIC (n ln(SSR / n) + k ln n, residuals in m) of a fit of
    force-driven tests over all its samples; NaN when a test is scored otherwise."""
    from .._diagnose import bic

    n = np.asarray(fit.num_samples, float)
    rmse_mm = np.asarray(fit.rmse_mm, float)
    if not np.all(np.isfinite(rmse_mm)) or np.sum(n) < 1:
        return math.nan
    total = int(np.sum(n))
    pooled = math.sqrt(float(np.sum(n * rmse_mm**2)) / total)
    return bic(pooled, total, len(fit.names), 1e3)


def _leading_pair(source) -> tuple[str, FitResult, str, FitResult, float]:
    """`(name_a, fit_a, name_b, fit_b, bic_now)` of a Diagnosis (its two candidates
    of lowest ΔBIC that were fitted and did not diverge) or of a pair of FitResults
    (BIC(b) - BIC(a) of the fits, NaN unless every test is force-driven)."""
    from .._diagnose import Diagnosis

    if isinstance(source, Diagnosis):
        ranked = sorted(
            (
                c
                for c in source.candidates
                if c.applicable
                and not c.diverging
                and c.fit is not None
                and math.isfinite(c.delta_bic)
            ),
            key=lambda c: c.delta_bic,
        )
        if len(ranked) < 2:
            raise ValueError(
                "`candidates`: the diagnosis has fewer than two fitted candidates "
                f"({[c.id for c in ranked]}); there is nothing to separate."
            )
        a, b = ranked[:2]
        fit_a, fit_b = typing.cast(FitResult, a.fit), typing.cast(FitResult, b.fit)
        return a.id, fit_a, b.id, fit_b, b.delta_bic - a.delta_bic
    pair = tuple(source) if isinstance(source, (tuple, list)) else ()
    if len(pair) != 2 or not all(isinstance(f, FitResult) for f in pair):
        raise ValueError(
            "`candidates` must be a jaxcable.Diagnosis or two jaxcable.FitResult, "
            f"got {type(source).__name__}."
        )
    first, second = typing.cast(tuple[FitResult, FitResult], pair)
    names = [type(f.model).__name__ for f in pair]
    if names[0] == names[1]:
        names = [f"{n} ({i + 1})" for i, n in enumerate(names)]
    return names[0], first, names[1], second, _bic(second) - _bic(first)


def design_discriminating_test(
    candidates, method: TestDesign, *, cable: Cable
) -> DiscriminatingTest:
    """Design the test that best separates two candidate models: after a diagnosis
    that cannot tell its two leading candidates apart, the test to run next.

    ```python
    method = jc.TestDesign(jc.TestBudget(duration_s=1200.0))
    separating = jc.design_discriminating_test(diagnosis, method, cable=cable)
    ```

    **The test** is the one of [`jaxcable.design_test`][]: `budget.blocks` blocks
    of a ramp to a load level, a hold, a ramp down and a rest at one crosshead
    speed, within the budget's duration, force and speed range.

    **Criterion**: T-optimality (Atkinson & Fedorov 1975), made symmetric. If a is
    true, the new test's elongations are a's; b, refitted to them and to the old
    data together, keeps the lack of fit

        T_ab = min_d |e_a - e_b - J_b d|^2 / sigma^2 + d^T P_b d,

    J_b the Jacobian of b's elongations in its parameters theta (log of a log-scaled
    one) through the simulation, P_b what the old data know of them (the inverse of
    its fit's covariance, with the posterior's prior of ln 10 on theta), sigma the
    elongation noise. The design maximises min(T_ab, T_ba) by Adam, the gradient
    through the rate-driven simulation of a (whose sample times both share) and
    both Jacobians, from three starting designs (the best kept). Expected
    BIC(wrong) - BIC(true) after the test is the BIC difference so far plus T (see
    `DiscriminatingTest.expected_delta_bic`).

    **Arguments:**

    - `candidates`: a [`jaxcable.Diagnosis`][] (its two candidates of lowest
        ΔBIC, fitted on its training data) or two [`jaxcable.FitResult`][] of the
        same tests.
    - `method`: a [`jaxcable.TestDesign`][]: the lab's budget (a
        [`jaxcable.TestBudget`][]; its `noise_mm`, default the smaller RMS residual
        of the two fits) and the optimiser's steps and learning rate.
    - `cable`: the cable to test (length, diameter, breaking load; its speed is
        designed, and is the speed of the standard protocol it is compared with).

    **Returns:**

    A [`jaxcable.DiscriminatingTest`][]: the protocol, its file, and the expected
    separation with it and with Park's standard protocol.

    **Raises:**

    `ValueError` naming the argument: fewer than two fitted candidates, a wrong
    type, parameters fitted per test.
    """
    _d.check_design_arguments(method, cable)
    budget = method.budget
    name_a, fit_a, name_b, fit_b, bic_now = _leading_pair(candidates)
    first = _d.knowledge_of(fit_a, budget.noise_mm)
    second = _d.knowledge_of(fit_b, budget.noise_mm)
    sigma = min(first.noise_m, second.noise_m)

    def criterion(protocol, c):
        traj = simulate_rate_test(first.model, c, protocol, method=_d.QUIET)
        t_ab, t_ba = separations(first, second, c, traj.time, protocol.force, sigma)
        # A smooth minimum (within about one unit of noise-sum of the smaller).
        low = -jnp.logaddexp(-t_ab, -t_ba)
        return -jnp.log1p(jnp.maximum(low, 0.0)), traj

    # min(T_ab, T_ba) has a kink wherever the two cross, and a design can stall
    # where one of them is flat: three starts, the best kept.
    protocol, c, parts, layout = _d.designed_protocol(
        method, cable, criterion, variants=(0, 1, 2)
    )
    traj = simulate_rate_test(first.model, c, protocol, method=_d.QUIET)
    duration = float(traj.time[-1])
    found = separations(first, second, c, traj.time, protocol.force, sigma)
    standard, usual = _d.standard_protocol(first.model, cable, budget, duration)
    std_traj = simulate_rate_test(first.model, usual, standard, method=_d.QUIET)
    baseline = separations(first, second, usual, std_traj.time, standard.force, sigma)
    result = DiscriminatingTest(
        protocol=protocol,
        cable=c,
        document={},
        candidates=(name_a, name_b),
        parameters=(len(fit_a.names), len(fit_b.names)),
        bic_now=float(bic_now),
        separation=(float(found[0]), float(found[1])),
        separation_standard=(float(baseline[0]), float(baseline[1])),
        samples=int(protocol.num_samples),
        samples_before=int(np.sum(fit_a.num_samples)),
        duration_s=duration,
        noise_m=float(sigma),
    )
    return result.with_document(cable, parts, layout, "discriminating-test")
