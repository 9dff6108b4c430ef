"""What an analysis of measured data is about ([`jaxcable.Problem`][]), and how the
least-squares fit solves it ([`jaxcable.LeastSquares`][]).

Every analysis of measured data ([`jaxcable.fit`][], [`jaxcable.fit_each`][],
[`jaxcable.sample_posterior`][], [`jaxcable.diagnose`][], [`jaxcable.design_test`][])
takes a `Problem` first and a method second, as optimistix's
`least_squares(fn, solver, y0)` takes its solver: each fact is given once.
"""

import os
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import optimistix as optx
from jaxtyping import PRNGKeyArray

from ._checks import require_int, require_number
from ._drive import DriveSpec
from ._io import TestData
from ._models import AbstractCableModel


def _as_tests(tests) -> Any:
    if isinstance(tests, TestData):
        return (tests,)
    if tests is None or isinstance(tests, (str, bytes, os.PathLike)):
        return tests  # refused with its name by __check_init__
    try:
        return tuple(tests)
    except TypeError:
        return tests


def _as_names(names) -> Any:
    if names is None or isinstance(names, str):
        return names  # a lone string is refused by __check_init__
    try:
        return tuple(names)
    except TypeError:
        return names


def _as_per_test(names) -> Any:
    return () if names is None else _as_names(names)


def _as_transforms(transforms) -> tuple[tuple[str, str], ...]:
    # A sorted tuple of pairs: hashable, so that a Problem's static part can key a
    # compiled program.
    if transforms is None:
        return ()
    if isinstance(transforms, Mapping):
        return tuple(sorted(transforms.items()))
    return transforms


def _as_drive(drive):
    if drive is None or isinstance(drive, str) or not isinstance(drive, Sequence):
        return drive
    return tuple(drive)


class Problem(eqx.Module):
    """What an analysis of measured data is about: a model, the tests it is to
    explain, and which of its parameters the data are to determine.

    ```python
    problem = jc.Problem(jc.BurgersModel(), tests)
    result = jc.fit(problem)  # jc.LeastSquares() by default
    ```

    **Fields:**

    - `model`: any [`jaxcable.AbstractCableModel`][] with scalar parameters: the
        start values of the fitted parameters and the values of the others.
    - `tests`: the [`jaxcable.TestData`][] to explain (one, or a sequence of them),
        with elongation and `length_mm` metadata; a test's boolean `mask` (True =
        fit the sample) excludes samples, e.g. slack, from the residuals.
    - `fit`: names of the parameters to fit; `None` (default) the model's
        identifiable set where the registry declares one (`IntegratedModel`:
        `PARK_IDENTIFIABLE`), else all inexact array fields.
    - `per_test`: names of parameters with one value per test (fitted whether or
        not they are in `fit`).
    - `transforms`: {name: `'log'` | `'linear'`} overriding a parameter's
        reparameterisation (see [`jaxcable.fit`][]); stored as sorted pairs.
    - `drive`: `"auto"` (default: each test's `metadata['control']`, else detected
        by [`jaxcable.detect_control`][]), `"force"`, `"elongation"`, a drive
        ([`jaxcable.FORCE_DRIVEN`][], [`jaxcable.ELONGATION_DRIVEN`][]), or a
        sequence of these, one per test.
    - `covariate`: the name of an extra column every test records
        (`test.extra[name]`: humidity, ...), set as `Cable.covariate` at each sample
        for a covariate-dependent model (a covariate extension,
        [`jaxcable.DiscoveredTerm`][]); `None` (default) when there is none (0
        throughout).

    **Raises:**

    `TypeError` or `ValueError` naming the field.
    """

    model: AbstractCableModel
    tests: tuple[TestData, ...] = eqx.field(converter=_as_tests)
    fit: tuple[str, ...] | None = eqx.field(
        default=None, converter=_as_names, static=True
    )
    per_test: tuple[str, ...] = eqx.field(
        default=(), converter=_as_per_test, static=True
    )
    transforms: tuple[tuple[str, str], ...] = eqx.field(
        default=(), converter=_as_transforms, static=True
    )
    drive: DriveSpec = eqx.field(default="auto", converter=_as_drive, static=True)
    covariate: str | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if not isinstance(self.model, AbstractCableModel):
            raise TypeError(
                "`model` must be a jaxcable.AbstractCableModel, got "
                f"{type(self.model).__name__}."
            )
        if not isinstance(self.tests, tuple):
            raise ValueError(
                "`tests` must be a TestData or a sequence of them (read files with "
                f"jaxcable.read_test), got {type(self.tests).__name__} {self.tests!r}."
            )
        if not self.tests:
            raise ValueError("`tests` is empty: give at least one TestData.")
        for i, t in enumerate(self.tests):
            if not isinstance(t, TestData):
                raise TypeError(
                    f"`tests[{i}]` must be a jaxcable.TestData, got {type(t).__name__}."
                )
        for name in ("fit", "per_test"):
            names = getattr(self, name)
            if names is None and name == "fit":
                continue
            if not isinstance(names, tuple) or not all(
                isinstance(n, str) for n in names
            ):
                raise TypeError(
                    f"`{name}` must be a sequence of parameter names, got {names!r}."
                )
        for pair in self.transforms:
            if (
                not isinstance(pair, tuple)
                or len(pair) != 2
                or pair[1] not in ("log", "linear")
            ):
                raise ValueError(
                    "`transforms` must map parameter names to 'log' or 'linear', "
                    f"got {self.transforms!r}."
                )
        if self.covariate is not None and not isinstance(self.covariate, str):
            raise TypeError(
                f"`covariate` must be a column name or None, got {self.covariate!r}."
            )

    @property
    def transform_map(self) -> dict[str, str]:
        """`transforms` as a dict {name: `'log'` | `'linear'`}."""
        return dict(self.transforms)

    def with_scaled_start(self) -> "Problem":
        """The same problem, its model's start values scaled to its tests
        ([`jaxcable.scaled_start`][] by the problem's drive): a start for a model
        whose defaults are far from the data (another cable, another material).

        **Returns:**

        This problem with the scaled model.

        **Raises:**

        `ValueError` naming `model` or `tests`, as [`jaxcable.scaled_start`][].
        """
        # Imported here: the fit imports this module.
        from ._fit import start_scaling

        model = start_scaling(self.model, self.tests, drive=self.drive).model
        return eqx.tree_at(lambda p: p.model, self, model)


class LeastSquares(eqx.Module):
    """The least-squares method of [`jaxcable.fit`][] and [`jaxcable.fit_each`][]:
    a Gauss-Newton-type solver, restarted from perturbed starts.

    **Fields:**

    - `solver`: an optimistix Gauss-Newton-type least-squares solver
        (`optx.LevenbergMarquardt`, `optx.GaussNewton`, `optx.Dogleg`, ...); `None`
        (default) Levenberg-Marquardt with rtol = atol = 1e-6 and textbook
        trust-region constants.
    - `max_steps`: solver steps per start (default 256).
    - `multistart`: number of starts, >= 1 (default 4): the data-scaled start and
        `multistart - 1` perturbations of it.
    - `spread`: standard deviation of the start perturbations of the unconstrained
        parameters (default 0.5: about +-50 % on a log parameter).
    - `key`: a `jax.random` key for the perturbations; `None` (default)
        `jax.random.key(0)`, so that a fit is reproducible unless asked otherwise.

    **Raises:**

    `ValueError` naming the field.
    """

    solver: optx.AbstractGaussNewton | None = None
    max_steps: int = eqx.field(default=256, static=True)
    multistart: int = eqx.field(default=4, static=True)
    spread: float = eqx.field(default=0.5, static=True)
    key: PRNGKeyArray | None = None

    def __check_init__(self):
        require_int("multistart", self.multistart, low=1)
        require_int("max_steps", self.max_steps, low=1)
        require_number("spread", self.spread, low=0)
        if self.solver is not None and not isinstance(
            self.solver, optx.AbstractGaussNewton
        ):
            raise TypeError(
                "`solver` must be an optimistix Gauss-Newton-type least-squares "
                f"solver (optx.LevenbergMarquardt, ...), got {self.solver!r}."
            )


class StreamingLeastSquares(eqx.Module):
    """The least-squares method of [`jaxcable.fit`][] for records of any length:
    Levenberg-Marquardt on the normal equations J^T J, J^T r accumulated sample by
    sample in one forward scan of each test, so that memory does not grow with the
    record (a robot's day at 100 Hz is 8.6 million samples; the Jacobian itself,
    n x p, is never formed). Each step costs about (p + 1) simulations of the record.
    Force-driven tests only (their elongation is scored), one start (the
    data-scaled one), no per-test parameters.

    **Fields:**

    - `max_steps`: the most Levenberg-Marquardt steps (default 100).
    - `rtol`, `atol`: converged when every coordinate of the step in the
        unconstrained parameters is below `atol + rtol |u|` (default 1e-8 both).
    - `damping`: the initial Marquardt damping, relative to the diagonal of J^T J
        (default 1e-6: nearly Gauss-Newton, which a rejected step damps; on a day's
        record of Park's model a start damping of 1e-3 ended in a poorer local
        minimum).

    **Raises:**

    `ValueError` or `TypeError` naming the field.
    """

    max_steps: int = eqx.field(default=100, static=True)
    rtol: float = eqx.field(default=1e-8, static=True)
    atol: float = eqx.field(default=1e-8, static=True)
    damping: float = eqx.field(default=1e-6, static=True)

    def __check_init__(self):
        require_int("max_steps", self.max_steps, low=1)
        require_number("rtol", self.rtol, low=0)
        require_number("atol", self.atol, low=0)
        require_number("damping", self.damping, low=0)
