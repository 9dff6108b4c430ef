"""The second stage of [`jaxcable.diagnose`][]: the base model fitted and scored on
every fold, its BIC and the structure of its residuals."""

import dataclasses
import math
from collections.abc import Callable
from typing import Any

from .._fit import FitResult, LevenbergMarquardt
from .._models import AbstractCableModel
from .._progress import AbstractProgressMeter
from .plan import Plan
from .scoring import BaseScore, Score, bic, score_folds
from .stack import Stack, stack_fitter, stack_of
from .structure import residual_structure


# The fits stop when an accepted step lowers the sum of squares by less than FTOL of
# it (`LevenbergMarquardt.ftol`): a candidate the data do not show otherwise may
# drift along a flat valley to `max_steps` (bedding-in on the bundled data: 23 or 256
# steps from run to run, as multi-threaded rounding picks the path). 1e-6 rather
# than scipy's 1e-8: on the 10-seed matrix (110 data sets,
# benchmarks/diagnose_matrix.py) every verdict is the same and the held-out RMSEs
# move by at most 0.16 %.
FTOL = 1e-6


@dataclasses.dataclass(frozen=True)
class BaseFit:
    """The base model fitted and scored on every fold.

    **Fields:**

    - `stack`: the base and every usable candidate as one model.
    - `fitter`: `fitter(active, multistart=1)`, the fit of the base (`active`
        None) or a candidate through the stack's one compiled kernel.
    - `score`: the base's [`Score`][].
    - `bic`: its BIC on the training samples.
    - `structure`: its residuals' structure over the whole tests
        ([`jaxcable.residual_structure`][]).
    """

    stack: Stack
    fitter: Callable
    score: Score
    bic: float
    structure: dict[str, Any]

    @property
    def fit(self) -> FitResult:
        """The base's fit on the first fold's training data."""
        return self.score.fits[0]

    @property
    def against(self) -> BaseScore:
        """What a candidate is compared with: held-out RMSE and BIC."""
        return BaseScore(self.score.heldout_rmse, self.bic)


def fit_base(
    plan: Plan,
    model: AbstractCableModel,
    *,
    multistart: int,
    max_steps: int,
    key,
    progress_meter: AbstractProgressMeter,
) -> BaseFit:
    """Fit the base `model` (its parameters `plan.names`) on every fold's training
    data and score it; its residuals' structure over the whole tests.

    **Raises:**

    `RuntimeError` when the base's fit fails.
    """
    how = plan.how
    # The base and every candidate are one model, each fit a choice of free
    # parameters: one compiled kernel (and one simulation) serves them all.
    stack = stack_of(model, [i for i in plan.ids if not plan.reasons[i]], plan.names)
    solver = LevenbergMarquardt(rtol=1e-6, atol=1e-6, ftol=FTOL)
    fitter = stack_fitter(
        stack, how, model, max_steps=max_steps, key=key, solver=solver
    )
    progress_meter.say(f"fitting the base model {type(model).__name__}")
    score = score_folds(
        plan.parts,
        lambda k: [stack.model(model, None)],
        fitter(None, multistart),
        how=how,
        same_tests=plan.split == "time",
    )
    fit = score.fits[0]
    if not math.isfinite(score.heldout_rmse):
        raise RuntimeError(
            f"jaxcable.diagnose: the base model's fit failed ({fit.message})."
        )
    # The base's residuals over whole tests in their scored channels, for the
    # structure analysis.
    residuals = how.residuals(
        stack.model(fit.model, None), plan.tests, range(len(plan.tests))
    )
    return BaseFit(
        stack=stack,
        fitter=fitter,
        score=score,
        bic=bic(score.train_rmse, score.num_train, len(fit.names), how.factor),
        structure=residual_structure(
            plan.tests, residuals, drives=how.drives, unit=how.unit
        ),
    )
