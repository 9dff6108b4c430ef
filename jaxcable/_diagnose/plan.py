"""The first stage of [`jaxcable.diagnose`][]: check the problem, fix the drives and
units once on the whole tests, split them into training and held-out data (the
blocked time split, or cross-validation folds by tests), and choose the candidates
the data can show and the base can carry."""

import dataclasses
from collections.abc import Sequence

import numpy as np

from .._fit import declared_parameters, test_id
from .._models import COVARIATE_EXTENSIONS, EXTENSIONS, identifiable
from .._problem import Problem
from .methods import Fold, HeldOut, splits, with_mask
from .scoring import Scoring, scoring


@dataclasses.dataclass(frozen=True)
class Plan:
    """The first stage of a diagnosis: the tests, how they are scored and split, and
    which candidates the data can show.

    **Fields:**

    - `tests`: the tests, each with a mask.
    - `names`: the base parameters to fit.
    - `how`: the drives and residual units (`Scoring`).
    - `parts`: the folds.
    - `heldout`: the [`jaxcable.HeldOut`][] the folds were made by.
    - `folds`: the number of folds by tests (the number of tests when leaving one
        out).
    - `ids`: the catalogue's candidates to try ([`jaxcable.EXTENSIONS`][] ids).
    - `reasons`: why each of `ids` cannot be tried ("" when it can).
    - `covariate_ids`: the covariates' extensions to try.
    - `columns`: the extra columns every test records (the covariates).
    """

    tests: list
    names: tuple[str, ...]
    how: Scoring
    parts: list[Fold]
    heldout: HeldOut
    folds: int
    ids: tuple[str, ...]
    reasons: dict[str, str]
    covariate_ids: tuple[str, ...]
    columns: tuple[str, ...]

    @property
    def split(self) -> str:
        """`"time"` or `"tests"`."""
        return self.heldout.split

    @property
    def time_fold(self) -> Fold:
        """The training and held-out tests of the time split."""
        return self.parts[0]

    @property
    def on_time_split_in_mm(self) -> bool:
        """Whether the covariates' candidates and the discovery run: on the time
        split of force-driven tests."""
        return self.split == "time" and self.how.unit == "mm"


def _check_problem(problem: Problem, heldout: HeldOut) -> int:
    """The number of folds by tests; `ValueError` naming what the diagnosis of
    `problem` cannot take."""
    tests = problem.tests
    for name in ("per_test", "transforms"):
        if getattr(problem, name):
            raise ValueError(
                f"`problem.{name}` must be empty: a diagnosis fits shared parameters "
                "with their own transforms."
            )
    if problem.fit is not None and not problem.fit:
        raise ValueError(
            "`problem.fit` is empty: name at least one base parameter to fit, or give "
            "None for the model's identifiable ones."
        )
    k = len(tests) if heldout.folds is None else heldout.folds
    if heldout.split == "tests" and len(tests) < 2:
        raise ValueError(
            "`split='tests'` (cross-validation by tests) needs >= 2 tests."
        )
    if heldout.split == "tests" and not 2 <= k <= len(tests):
        raise ValueError(f"`folds` must be an int in [2, {len(tests)}], got {k!r}.")
    for i, t in enumerate(tests):
        if t.elongation is None:
            raise ValueError(
                f"`tests[{i}]` ({test_id(t, i)}) has no elongation to diagnose."
            )
    return k


def _reasons(tests, model, catalogue) -> dict[str, str]:
    """Why each catalogue candidate cannot be tried: the data cannot show it
    (`applicability`) or the base cannot carry it (`wrap`); "" when it can."""
    reasons = {}
    for ext_id in catalogue:
        reason = EXTENSIONS[ext_id].applicability(tests)
        if not reason:
            try:
                EXTENSIONS[ext_id].wrap(model)
            except ValueError as e:
                reason = str(e)
        reasons[ext_id] = reason
    return reasons


def choose_candidates(
    problem: Problem, heldout: HeldOut, candidates: Sequence[str]
) -> Plan:
    """Check `problem`, resolve the drives once on the whole tests, split them by
    `heldout`, and choose among `candidates` (extension ids) those the data can show
    and the base can carry (`applicability`, then `wrap`). `problem.covariate`: the
    extra column the base reads (a covariate's extension named in an earlier round),
    then the only column of the covariates' candidates and of the discovery.

    **Returns:**

    A `Plan`.

    **Raises:**

    `ValueError` naming the first bad argument.
    """
    k = _check_problem(problem, heldout)
    tests = list(problem.tests)
    columns = tuple(covariate_columns(tests))
    if problem.covariate is not None:
        # `Cable.covariate` is one column: the one the base already reads.
        columns = (problem.covariate,)
    tests = [
        t if t.mask is not None else with_mask(t, np.ones(len(t.time), bool))
        for t in tests
    ]
    model = problem.model
    names = problem.fit if problem.fit is not None else identifiable(model)
    if names is None:  # not in the registry: every parameter
        names = tuple(declared_parameters(model))
    catalogue = tuple(i for i in candidates if i in EXTENSIONS)
    return Plan(
        tests=tests,
        names=names,
        # The drives and residual units, once for the whole tests: no fold
        # re-detects.
        how=scoring(tests, problem.drive, problem.covariate),
        parts=splits(tests, heldout, k),
        heldout=heldout,
        folds=k,
        ids=catalogue,
        reasons=_reasons(tests, model, catalogue),
        # The covariates' extensions are fitted apart, on the time split.
        covariate_ids=tuple(i for i in candidates if i in COVARIATE_EXTENSIONS),
        columns=columns,
    )


def covariate_columns(tests) -> list[str]:
    """The extra columns every test records, numeric and not constant in all of
    them: each may drive a discovered term or a covariate's extension."""
    common = None
    for t in tests:
        names = set(t.extra or {})
        common = names if common is None else common & names
    out = []
    for name in sorted(common or ()):
        values = [np.asarray(t.extra[name], float) for t in tests]
        if all(np.all(np.isfinite(v)) for v in values) and any(
            np.ptp(v) > 0 for v in values
        ):
            out.append(name)
    return out
