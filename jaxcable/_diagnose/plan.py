"""The first stage of [`jaxcable.diagnose`][]: check its arguments, fix the drives and
units once on the whole tests, split them into training and held-out data, and choose
the candidates the data can show and the base can carry."""

import dataclasses
from collections.abc import Sequence
from typing import Literal

import numpy as np

from .._fit import as_test_list, declared_parameters, test_id
from .._models import (
    COVARIATE_EXTENSIONS,
    EXTENSIONS,
    AbstractCableModel,
    identifiable,
)
from .heldout import Fold, splits, with_mask
from .scoring import Scoring, scoring


@dataclasses.dataclass(frozen=True)
class Plan:
    """The first stage of a diagnosis: the tests, how they are scored and split, and
    which candidates the data can show.

    **Fields:**

    - `tests`: the tests, each with a mask.
    - `names`: the base parameters to fit.
    - `how`: the drives and residual units ([`Scoring`][]).
    - `parts`: the folds.
    - `split`, `holdout`, `folds`: as given to [`jaxcable.diagnose`][].
    - `ids`: the catalogue's candidates to try ([`jaxcable.EXTENSIONS`][] ids).
    - `reasons`: why each of `ids` cannot be tried ("" when it can).
    - `covariate_ids`: the covariates' extensions to try.
    - `columns`: the extra columns every test records (the covariates).
    """

    tests: list
    names: tuple[str, ...]
    how: Scoring
    parts: list[Fold]
    split: str
    holdout: float
    folds: int
    ids: tuple[str, ...]
    reasons: dict[str, str]
    covariate_ids: tuple[str, ...]
    columns: tuple[str, ...]

    @property
    def time_fold(self) -> Fold:
        """The training and held-out tests of the time split."""
        return self.parts[0]

    @property
    def on_time_split_in_mm(self) -> bool:
        """Whether the covariates' candidates and the discovery run: on the time
        split of force-driven tests."""
        return self.split == "time" and self.how.unit == "mm"

    def split_text(self) -> str:
        """How held-out data were chosen, in words."""
        if self.split == "time":
            return f"last {self.holdout:.0%} of every test's samples"
        if self.folds == len(self.tests):
            return "leave-one-test-out"
        return f"{self.folds}-fold by tests"


def _check_arguments(tests, model, ids, split, holdout, k) -> None:
    """Raise `ValueError` naming the first bad argument of `diagnose`."""
    if not isinstance(model, AbstractCableModel):
        raise ValueError(
            f"`model` must be a jaxcable model, got {type(model).__name__}."
        )
    known = [*EXTENSIONS, *COVARIATE_EXTENSIONS]
    unknown = [c for c in ids if c not in known]
    if unknown:
        raise ValueError(f"`candidates` names {unknown}; known extensions: {known}.")
    if split not in ("time", "tests"):
        raise ValueError(f"`split` must be 'time' or 'tests', got {split!r}.")
    if not (isinstance(holdout, (int, float)) and 0.0 < holdout <= 0.9):
        raise ValueError(f"`holdout` must be in (0, 0.9], got {holdout!r}.")
    if split == "tests" and len(tests) < 2:
        raise ValueError(
            "`split='tests'` (cross-validation by tests) needs >= 2 tests."
        )
    if split == "tests" and not (isinstance(k, int) and 2 <= k <= len(tests)):
        raise ValueError(f"`folds` must be an int in [2, {len(tests)}], got {k!r}.")
    for i, t in enumerate(tests):
        if getattr(t, "elongation", None) is None:
            raise ValueError(
                f"`tests[{i}]` ({test_id(t, i)}) has no elongation to diagnose."
            )


def choose_candidates(
    tests,
    model: AbstractCableModel,
    *,
    fit_names: Sequence[str] | None,
    candidates: Sequence[str] | None,
    split: Literal["time", "tests"],
    holdout: float,
    folds: int | None,
    drive,
    covariate: str | None = None,
) -> Plan:
    """Check the arguments of [`jaxcable.diagnose`][] (same names), resolve the
    drives once on the whole tests, split them, and choose the candidates the data
    can show and the base can carry (`applicability`, then `wrap`). `covariate`: the
    extra column the base reads (a covariate's extension named in an earlier round),
    then the only column of the covariates' candidates and of the discovery.

    **Returns:**

    A [`Plan`][].

    **Raises:**

    `ValueError` naming the first bad argument.
    """
    tests = as_test_list(tests)
    ids = [*EXTENSIONS, *COVARIATE_EXTENSIONS] if candidates is None else [*candidates]
    k = len(tests) if folds is None else folds
    _check_arguments(tests, model, ids, split, holdout, k)
    if fit_names is not None and not [*fit_names]:
        raise ValueError(
            "`fit_names` is empty: name at least one base parameter to fit, or give "
            "None for the model's identifiable ones."
        )
    columns = tuple(covariate_columns(tests))
    if covariate is not None:
        # `Cable.covariate` is one column: the one the base already reads.
        columns = (covariate,)
    tests = [
        t
        if getattr(t, "mask", None) is not None
        else with_mask(t, np.ones(len(t.time), bool))
        for t in tests
    ]
    names = tuple(fit_names) if fit_names is not None else identifiable(model)
    if names is None:  # not in the registry: every parameter
        names = tuple(declared_parameters(model))
    # The drives and residual units, once for the whole tests: no fold re-detects.
    how = scoring(tests, drive, covariate)
    parts = splits(tests, split, holdout, k)
    catalogue = tuple(i for i in ids if i in EXTENSIONS)
    reasons = {}
    for ext_id in catalogue:
        reason = EXTENSIONS[ext_id].applicability(tests)
        if not reason:
            try:
                EXTENSIONS[ext_id].wrap(model)
            except ValueError as e:
                reason = str(e)
        reasons[ext_id] = reason
    return Plan(
        tests=tests,
        names=names,
        how=how,
        parts=parts,
        split=split,
        holdout=holdout,
        folds=k,
        ids=catalogue,
        reasons=reasons,
        # The covariates' extensions are fitted apart, on the time split.
        covariate_ids=tuple(i for i in ids if i in COVARIATE_EXTENSIONS),
        columns=columns,
    )


def covariate_columns(tests) -> list[str]:
    """The extra columns every test records, numeric and not constant in all of
    them: each may drive a discovered term or a covariate's extension."""
    common = None
    for t in tests:
        names = set(getattr(t, "extra", None) or {})
        common = names if common is None else common & names
    out = []
    for name in sorted(common or ()):
        values = [np.asarray(t.extra[name], float) for t in tests]
        if all(np.all(np.isfinite(v)) for v in values) and any(
            np.ptp(v) > 0 for v in values
        ):
            out.append(name)
    return out
