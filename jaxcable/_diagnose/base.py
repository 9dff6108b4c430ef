"""The second stage of [`jaxcable.diagnose`][]: the base model fitted and scored on
every fold, its BIC and the structure of its residuals; and the one model, the
stack, through which the base and every candidate are fitted.
The base model and every candidate of a diagnosis as one model, so that one
compiled kernel fits them all.

The candidate extensions are nested around the base in [`jaxcable.EXTENSIONS`][]'s
order (creep changes innermost, then temperature, then the apparatus), each at the
null value of its effect (`switched_off`, the base exactly) except the one being
fitted, which starts from its `wrap` values. A fit is then which parameters are free
(`jaxcable._fit.fit_subset`): the base's, plus the candidate's effect fields. The
results are given back as the base's or the candidate's own model and names
(`Stack.result_of`), as if each had been fitted alone: at the null values the other
layers change nothing.
"""

import dataclasses
import math
import warnings
from collections.abc import Callable
from typing import Any

import equinox as eqx

from .._fit import (
    FitResult,
    IdentifiabilityWarning,
    LevenbergMarquardt,
    field_at,
    fit_subset,
    shared_layout,
)
from .._models import EXTENSIONS, AbstractCableModel
from .._problem import LeastSquares
from .._progress import AbstractProgressMeter
from .plan import Plan
from .scoring import BaseScore, Score, bic, score_folds
from .structure import residual_structure


@dataclasses.dataclass(frozen=True)
class Stack:
    """The extensions `ids` nested around a base model, innermost first.

    **Fields:**

    - `ids`: the candidate ids in the stack (those that can wrap the base).
    - `base_names`: the base's fitted parameters (its own paths).
    """

    ids: tuple[str, ...]
    base_names: tuple[str, ...]

    @property
    def base_prefix(self) -> str:
        return "base." * len(self.ids)

    def _prefix(self, ext_id: str) -> str:
        """The path of the layer `ext_id` in the stack, with a trailing dot ('' for
        the outermost)."""
        return "base." * (len(self.ids) - 1 - self.ids.index(ext_id))

    def model(self, base: AbstractCableModel, active: str | None) -> AbstractCableModel:
        """The stack around `base`: every layer off but `active` (None: all off;
        `"all"`: every layer at its start values, for the layout)."""
        m = base
        for ext_id in self.ids:
            cls = EXTENSIONS[ext_id]
            on = active in (ext_id, "all")
            m = cls.wrap(m) if on else cls.switched_off(m)
        return m

    def free(self, active: str | None) -> tuple[str, ...]:
        """The stack's paths of the parameters a fit of `active` frees."""
        names = tuple(self.base_prefix + n for n in self.base_names)
        if active is None:
            return names
        own = EXTENSIONS[active].EFFECT_FIELDS
        return names + tuple(self._prefix(active) + f for f in own)

    @property
    def size(self) -> int:
        """The most parameters any fit frees: the solver's vector length."""
        return len(self.base_names) + max(
            (len(EXTENSIONS[i].EFFECT_FIELDS) for i in self.ids), default=0
        )

    def layout(self, base: AbstractCableModel, tests, drive):
        """The layout of every parameter any fit frees."""
        union = tuple(dict.fromkeys(n for i in (None, *self.ids) for n in self.free(i)))
        return shared_layout(self.model(base, "all"), tests, union, drive=drive)

    def fit_stacked(self, start, tests, layout, active, **kwargs) -> FitResult:
        """Fit `start` (a stack) with the parameters of `active` free: the result
        with the stack's model and paths."""
        return fit_subset(
            start, tests, layout, self.free(active), size=self.size, **kwargs
        )

    def fit(self, start, tests, layout, active, **kwargs) -> FitResult:
        """`fit_stacked`, the result as the base's or the candidate's own (see
        `result_of`)."""
        stacked = self.fit_stacked(start, tests, layout, active, **kwargs)
        return self.result_of(stacked, active)

    def own_model(self, stack: AbstractCableModel, active: str | None):
        """The base model (`active` None) or the candidate's extension around it,
        with the values of `stack`."""
        base = field_at(stack, self.base_prefix[:-1]) if self.ids else stack
        if active is None:
            return base
        layer = (
            field_at(stack, self._prefix(active)[:-1])
            if self._prefix(active)
            else stack
        )
        return eqx.tree_at(lambda m: m.base, layer, base)

    def result_of(self, result: FitResult, active: str | None) -> FitResult:
        """`result` of a stack fit with the model, per-test models and names of the
        base (`active` None) or of `active` around it (`base.NAME` and its fields)."""
        prefix = self.base_prefix
        outer = "" if active is None else self._prefix(active)

        def own(name: str) -> str:
            if name.startswith(prefix):
                return ("" if active is None else "base.") + name[len(prefix) :]
            return name[len(outer) :]

        return dataclasses.replace(
            result,
            model=self.own_model(result.model, active),
            models=tuple(self.own_model(m, active) for m in result.models),
            names=tuple(own(n) for n in result.names),
        )


def stack_of(base: AbstractCableModel, ids, base_names) -> Stack:
    """The `Stack` of the candidates `ids` that can wrap `base` (`wrap` raises
    for the others, e.g. `hereditary` around a model without Park's creep)."""
    usable = []
    m = base
    for ext_id in ids:
        try:
            m = EXTENSIONS[ext_id].switched_off(m)
        except ValueError:
            continue
        usable.append(ext_id)
    return Stack(tuple(usable), tuple(base_names))


def stack_fitter(stack: Stack, how, base_model, method: LeastSquares):
    """`fitter(active, multistart=1)`: the `fitter` of `score_folds` for the base
    (`active` None) or a candidate, every one through the stack's one compiled kernel
    (a layout per number of training tests), with the steps, spread, key and solver
    of `method` (its solver None: `diagnosis_solver`)."""
    solver = diagnosis_solver() if method.solver is None else method.solver
    layouts: dict[int, object] = {}

    def layout(tests, drives):
        if len(tests) not in layouts:
            layouts[len(tests)] = stack.layout(base_model, tests, drives)
        return layouts[len(tests)]

    def fitter(active, multistart=1):
        def run(start, tests, index):
            drives = [how.drive_names[i] for i in index]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", IdentifiabilityWarning)
                raw = stack.fit_stacked(
                    start,
                    tests,
                    layout(tests, drives),
                    active,
                    throw=False,
                    drive=drives,
                    covariate=how.covariate,
                    multistart=multistart,
                    max_steps=method.max_steps,
                    spread=method.spread,
                    key=method.key,
                    solver=solver,
                )
            return stack.result_of(raw, active), raw.model

        return run

    return fitter


# The fits stop when an accepted step lowers the sum of squares by less than FTOL of
# it (`LevenbergMarquardt.ftol`): a candidate the data do not show otherwise may
# drift along a flat valley to `max_steps` (bedding-in on the bundled data: 23 or 256
# steps from run to run, as multi-threaded rounding picks the path). 1e-6 rather
# than scipy's 1e-8: on the 10-seed matrix (110 data sets,
# benchmarks/diagnose_matrix.py) every verdict is the same and the held-out RMSEs
# move by at most 0.16 %.
FTOL = 1e-6


def diagnosis_solver() -> LevenbergMarquardt:
    """The diagnosis's own solver: Levenberg-Marquardt with rtol = atol = 1e-6,
    stopping too when a step lowers the sum of squares by less than `FTOL`."""
    return LevenbergMarquardt(rtol=1e-6, atol=1e-6, ftol=FTOL)


@dataclasses.dataclass(frozen=True)
class BaseFit:
    """The base model fitted and scored on every fold.

    **Fields:**

    - `stack`: the base and every usable candidate as one model.
    - `fitter`: `fitter(active, multistart=1)`, the fit of the base (`active`
        None) or a candidate through the stack's one compiled kernel.
    - `score`: the base's `Score`.
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
    method: LeastSquares,
    progress_meter: AbstractProgressMeter,
) -> BaseFit:
    """Fit the base `model` (its parameters `plan.names`) on every fold's training
    data by `method` and score it; its residuals' structure over the whole tests.

    **Raises:**

    `RuntimeError` when the base's fit fails.
    """
    how = plan.how
    # The base and every candidate are one model, each fit a choice of free
    # parameters: one compiled kernel (and one simulation) serves them all.
    stack = stack_of(model, [i for i in plan.ids if not plan.reasons[i]], plan.names)
    fitter = stack_fitter(stack, how, model, method)
    progress_meter.say(f"fitting the base model {type(model).__name__}")
    score = score_folds(
        plan.parts,
        lambda k: [stack.model(model, None)],
        fitter(None, method.multistart),
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
