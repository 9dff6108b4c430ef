"""`jaxcable.design_test` and its outcome, `DesignedTest`: the protocol, its file,
and what it is expected to teach beside Park's standard protocol of the same
duration."""

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._cable import Cable
from .._drive import Protocol, simulate_rate_test
from .._fit import FitResult
from . import design as _d
from .methods import TestDesign
from .result import Posterior


@dataclasses.dataclass(frozen=True)
class DesignedTest(_d.DesignedProtocol):
    """The outcome of [`jaxcable.design_test`][].

    **Fields:**

    - `protocol`: the designed test, a [`jaxcable.Protocol`][].
    - `cable`: the cable at the designed crosshead speed.
    - `document`: the protocol file (a dict; `to_json` writes it) that
        `jaxcable simulate` and a tester run.
    - `names`: the fitted parameters.
    - `targets`: the parameters the design aimed at.
    - `sd_before`: each parameter's standard deviation now (relative, for a
        positive one: of its logarithm).
    - `sd_after`: expected after adding the designed test (linearised).
    - `sd_standard`: expected after adding Park's 10-cycle protocol of the same
        duration and largest force instead.
    - `duration_s`: the designed test's simulated duration, s.
    - `criterion`: log det of the targets' covariance: `(before, designed,
        standard)`.
    """

    names: tuple[str, ...]
    targets: tuple[str, ...]
    sd_before: np.ndarray
    sd_after: np.ndarray
    sd_standard: np.ndarray
    duration_s: float
    criterion: tuple[float, float, float]

    def summary(self) -> str:
        """What the test is, what it is expected to gain, and why."""
        segs = self.document["segments"]
        lines = [
            f"designed test: {self.document['rate_mm_per_min']:.3g} mm/min, "
            f"{len(segs)} segments, {self.duration_s:.0f} s, "
            f"{self.protocol.num_samples} samples",
        ]
        for s in segs:
            lines.append("  " + ", ".join(f"{k} {v:.4g}" for k, v in s.items()))
        lines += [
            "",
            f"{'parameter':<12} {'sd now':>9} {'designed':>9} {'standard':>9}  "
            "(relative sd; * = target)",
        ]
        for i, n in enumerate(self.names):
            mark = "*" if n in self.targets else " "
            lines.append(
                f"{mark}{n[:11]:<11} {self.sd_before[i]:>9.3g} "
                f"{self.sd_after[i]:>9.3g} {self.sd_standard[i]:>9.3g}"
            )
        lines += ["", self.why()]
        return "\n".join(lines)

    def why(self) -> str:
        """One paragraph: the expected gain on the targets against the standard
        protocol, and the information criterion behind it."""
        idx = [self.names.index(n) for n in self.targets]
        shrink = self.sd_before[idx] / self.sd_after[idx]
        standard = self.sd_before[idx] / self.sd_standard[idx]
        before, designed, std = self.criterion
        return (
            f"The least identified parameters ({', '.join(self.targets)}) are the "
            "targets: the test maximises the information about them (D_s-optimal: "
            "the log-determinant of their covariance after the test, "
            f"{before:.2f} now -> {designed:.2f}; Park's 10-cycle protocol of the "
            f"same duration: {std:.2f}). Their standard deviations shrink by "
            + ", ".join(f"{a:.2g}x" for a in shrink)
            + " (standard protocol: "
            + ", ".join(f"{b:.2g}x" for b in standard)
            + ")."
        )


def _precision_after(knowledge: _d.Knowledge, cable: Cable, protocol: Protocol):
    """The information after a rate-driven test: simulate it (its sample times are
    solved), then the Fisher information of it as the fit would see it."""
    traj = simulate_rate_test(knowledge.model, cable, protocol, method=_d.QUIET)
    info = _d.information(knowledge, cable, traj.time, protocol.force)
    return jnp.asarray(knowledge.precision()) + info, traj


def design_test(
    known: FitResult | Posterior,
    method: TestDesign,
    *,
    cable: Cable,
    targets=None,
) -> DesignedTest:
    """Design the next test: the protocol that teaches most about the parameters
    known least.

    ```python
    method = jc.TestDesign(jc.TestBudget(duration_s=1200.0), steps=40)
    designed = jc.design_test(fit, method, cable=tests[0].cable())
    ```

    **What is known**: a [`jaxcable.FitResult`][] (its fitted model and linearised
    covariance) or a [`jaxcable.Posterior`][] (its median model and the covariance
    of its draws), both on the scale theta (log of a parameter a fit log-scales), with the
    posterior's prior (ln 10 on theta) added so that a parameter the data do not
    determine has a finite variance.

    **The test**: `budget.blocks` blocks, each a ramp to a load level, a hold, a
    ramp down to 0 N and a rest, at one crosshead speed. Design variables: the
    levels (up to `budget.max_force_fraction` of the breaking load), the hold and
    rest durations (shares of the budget's duration left by the ramps) and the
    speed (in `budget.speed_mm_per_min`); the samples are fixed by `budget.samples`.

    **Criterion**: D_s-optimality. With F the Fisher information of the test (J^T J
    / sigma^2, J the Jacobian of its elongations in theta through the simulation,
    the sample times those the tester's speed gives, sigma the elongation noise),
    minimise log det of the targets' block of (I_now + F)^-1. Adam on the design
    variables, the gradient through the rate-driven simulation (implicit
    derivatives of its time solve) and the Jacobian; the ramps' duration is
    re-estimated between steps.

    After an ambiguous diagnosis, the test that separates its two leading
    candidates is [`jaxcable.design_discriminating_test`][]'s.

    **Arguments:**

    - `known`: what is known, a [`jaxcable.FitResult`][] or a
        [`jaxcable.Posterior`][] (without parameters fitted per test).
    - `method`: a [`jaxcable.TestDesign`][]: the lab's budget (a
        [`jaxcable.TestBudget`][]) and the optimiser's steps and learning rate.
    - `cable`: the cable to test (length, diameter, breaking load; its speed is
        designed, and is the speed of the standard protocol it is compared with).
    - `targets`: parameter names to learn about; default the least identified one
        and those within a factor 3 of its standard deviation (at most 3).

    **Returns:**

    A [`jaxcable.DesignedTest`][]: the protocol, its file, and the expected
    standard deviations with it and with Park's standard protocol.

    **Raises:**

    `ValueError` naming the argument: `known` of another kind (a diagnosis or two
    fits included), `method`, `cable`, unknown `targets`, a noise that cannot be
    read from the fit (`budget.noise_mm`).
    """
    _d.check_design_arguments(method, cable)
    budget = method.budget
    knowledge = _d.knowledge_of(known, budget.noise_mm)
    idx = _d.default_targets(knowledge, targets)

    def criterion(protocol, c):
        precision, traj = _precision_after(knowledge, c, protocol)
        return _d.log_det_subset(precision, idx), traj

    protocol, c, parts, layout = _d.designed_protocol(method, cable, criterion)
    precision, traj = _precision_after(knowledge, c, protocol)
    before = np.linalg.inv(knowledge.precision())
    after = np.linalg.inv(np.asarray(precision))
    duration = float(traj.time[-1])
    standard, usual = _d.standard_protocol(knowledge.model, cable, budget, duration)
    std_precision, _ = _precision_after(knowledge, usual, standard)
    std_cov = np.linalg.inv(np.asarray(std_precision))

    def crit(cov):
        return float(np.linalg.slogdet(cov[np.ix_(idx, idx)])[1])

    result = DesignedTest(
        protocol=protocol,
        cable=c,
        document={},
        names=knowledge.names,
        targets=tuple(knowledge.names[i] for i in idx),
        sd_before=np.sqrt(np.diag(before)),
        sd_after=np.sqrt(np.diag(after)),
        sd_standard=np.sqrt(np.diag(std_cov)),
        duration_s=duration,
        criterion=(crit(before), crit(after), crit(std_cov)),
    )
    return result.with_document(cable, parts, layout, "designed-test")
