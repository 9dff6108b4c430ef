"""Discovery of a term the base model lacks: sparse regression of the base's strain
residual on a library of integrated terms ([`jaxcable.DiscoveredTerm`][]) and the
base's own parameter sensitivities, the sparsity chosen on held-out samples, then a
joint Levenberg-Marquardt fit of the base with the chosen terms, reported as an
equation with units; and the diagnosis's discovery stage, over no covariate and
every recorded one, scored like the catalogue's candidates.

Discovery runs on force-driven tests (the model driven by the measured force, the
elongation scored): the library terms are functions of the force history and the
covariate, which an elongation-driven test does not prescribe.
"""

import dataclasses
import math
from typing import Any, NamedTuple

import numpy as np

from .._drive import FORCE_DRIVEN, as_test_drive
from .._fit import FitResult, responses, test_id
from .._models import AbstractCableModel
from .._problem import Problem
from .library import (
    ACCEL_FIELDS,
    COVARIATE_TERMS,
    MAX_TERMS,
    MEMORY_TERMS,
    RATE_FIELDS,
    TERMS,
    THETA_FIELDS,
    DiscoveredTerm,
    accel_grid,
    accel_unit,
    base_fit_names,
    base_start,
    covariate_in,
    damage_integral,
    library,
    memory_equation,
    memory_library,
    rate_grid,
    sensitivities,
    step_inputs,
    theta_unit,
)
from .methods import Discovery, check_arguments, fit_quietly, heldout_start
from .scoring import force_scoring


@dataclasses.dataclass(frozen=True)
class DiscoveryResult:
    """What [`jaxcable.discover`][] found.

    **Fields:**

    - `terms`: the chosen term ids (empty: nothing found).
    - `coefficients`: their regression estimates, 1/s per unit of the term.
    - `model`: the `DiscoveredTerm` around the base to fit (start values from the
        regression); the base itself when no term was found.
    - `fit`: the joint fit (base parameters and the chosen thetas), or None.
    - `values`, `stderr`: the fitted thetas and their standard errors (1/s per unit
        of the term; the regression's with NaN errors when there is no fit).
    - `units`: the unit of each theta.
    - `equation`: `d(eps)/dt = ...` with coefficients +- standard errors and units.
    - `covariate`: the covariate column, or None.
    - `heldout_rmse_mm`: `(base, discovered)` RMSE on the held-out samples, mm.
    - `gain_pct`: 100 (1 - discovered / base) of the held-out RMSE.
    - `path`: `(terms, held-out RMSE of the residual, mm)` of every support the
        thresholds gave, the empty one first (a term with memory as `term@rate`, a
        damage as `term@b,a=a`).
    - `rates`: each term's rate k or exponent b (terms with memory), NaN for the
        stateless ones.
    - `accels`: each damage's acceleration a (0 for the other terms with memory,
        NaN for the stateless ones).
    - `support`: the chosen support as it appears in `path`.
    """

    terms: tuple[str, ...]
    coefficients: np.ndarray
    model: AbstractCableModel
    fit: FitResult | None
    values: np.ndarray
    stderr: np.ndarray
    units: tuple[str, ...]
    equation: str
    covariate: str | None
    heldout_rmse_mm: tuple[float, float]
    gain_pct: float
    path: tuple[tuple[tuple[str, ...], float], ...]
    rates: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    accels: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    support: tuple[str, ...] = ()

    def describe(self) -> dict[str, Any]:
        """The term for [`jaxcable.Diagnosis`][]`.discovered`: the equation, terms,
        covariate, coefficients with standard errors and units, held-out RMSEs and
        gain."""
        return {
            "equation": self.equation,
            "terms": list(self.terms),
            "covariate": self.covariate,
            "values": [float(v) for v in self.values],
            "stderr": [float(s) for s in self.stderr],
            "units": list(self.units),
            "rates": [float(r) for r in self.rates],
            "accels": [float(a) for a in self.accels],
            "heldout_rmse_mm": [float(x) for x in self.heldout_rmse_mm],
            "gain_pct": float(self.gain_pct),
        }

    def size(self) -> tuple[float, float, str, str]:
        """`(value, standard error, unit, name)` of its best-determined theta, the
        size of the discovered candidate (a support may carry a weak companion
        term, which the forward selection kept for a small held-out gain)."""
        values = np.asarray(self.values, float)
        errors = np.asarray(self.stderr, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            zs = np.where(errors > 0, np.abs(values) / errors, np.inf)
        k = int(np.nanargmax(np.where(np.isfinite(values), zs, -1.0)))
        return values[k], errors[k], self.units[k], f"theta{k} ({self.terms[k]})"


def _equation(terms, values, stderr, covariate, rates, accels) -> str:
    """`d(eps)/dt = v (+-se) unit * symbol + ...` (`0` without terms), then each
    term with memory as `eps += ...` with its state's equation."""
    name = covariate or "c"
    parts, states = [], []
    for t, v, se, rate, accel in zip(terms, values, stderr, rates, accels):
        err = f" (+-{se:.2g})" if math.isfinite(se) else ""
        value = f"{v:.3g}{err} {theta_unit(t, f'[{name}]')}"
        if t in MEMORY_TERMS:
            rate_unit = covariate_in(MEMORY_TERMS[t][2], f"[{name}]")
            rate_text = f"{rate:.3g}" + ("" if rate_unit == "-" else f" {rate_unit}")
            accel_text = f"{accel:.3g} {accel_unit(t)}" if accel else "0"
            states.append(
                "eps += " + memory_equation(t, value, rate_text, name, accel_text)
            )
            continue
        symbol = TERMS[t][0].replace("c", name) if t in COVARIATE_TERMS else TERMS[t][0]
        parts.append(f"{value} * {symbol}")
    text = "d(eps)/dt = " + (" + ".join(parts) if parts else "0")
    return "; ".join(states) if states and not parts else "; ".join([text, *states])


def discover(
    base_fit: FitResult, problem: Problem, method: Discovery = Discovery()
) -> DiscoveryResult:
    """Find at most four library terms whose integrated strain explains the residual
    of a fitted base model, and fit them jointly with the base.

    ```python
    base_fit = jc.fit(problem)  # on the training samples, for an honest score
    found = jc.discover(base_fit, problem)
    print(found.equation)
    ```

    1. The residual strain r = (measured - model) / L0 of `base_fit`'s model along
        every force-driven test; each library term's strain per unit theta eps_k
        (see `library`); and the sensitivity of the model's strain to each of
        the base's fitted parameters (its Jacobian at the fit).
    2. Forward selection of at most four terms: each support is the least-squares
        fit of r on its terms' strains AND every base sensitivity over the training
        samples (the base's parameters move with every candidate support, so that a
        term the base can mimic by refitting is not chosen), scored by the RMSE of
        what it leaves on the held-out samples.
    3. The support of least held-out RMSE is chosen if it beats no term (the base
        refitted to first order) by `method.min_gain_pct` (else none), and of
        near-equal ones (within 1 %) the fewest terms.
    4. `DiscoveredTerm(base, theta, terms)` is fitted by [`jaxcable.fit`][]
        (force-driven, the base's fitted parameters and the chosen thetas) on the
        training samples, and scored on the held-out ones.

    **Arguments:**

    - `base_fit`: a [`jaxcable.FitResult`][] of the base model (on the training
        samples of these tests, for an honest held-out score).
    - `problem`: a [`jaxcable.Problem`][] whose `tests` are searched (only the
        force-driven ones: a test not force-driven in `base_fit` is skipped) with
        its `covariate` (an extra column every test records, its unit the
        column's; None: no covariate terms). Its model and fitted names are not
        read: the base is `base_fit`'s.
    - `method`: a [`jaxcable.Discovery`][] (default `jc.Discovery()`: every term,
        the last 30 % of every test held out, a 5 % gain, a joint fit from one
        start).

    **Returns:**

    A [`jaxcable.DiscoveryResult`][].

    **Raises:**

    `TypeError` naming `problem` or `method` of another type; `ValueError` when no
    test is force-driven or the covariate column is missing (naming the test).
    """
    check_arguments(problem, method, Discovery)
    return discover_terms(
        base_fit, list(problem.tests), problem.covariate, None, method
    )


def discover_terms(
    base_fit: FitResult, tests: list, covariate: str | None, held, method: Discovery
) -> DiscoveryResult:
    """`discover` of `tests` with the extra column `covariate` (or none), held
    out: `held` (one boolean array per test, True where a sample is held out), else
    the last `method.heldout.fraction` of every test."""
    keep, tests, held = _force_driven(base_fit, tests, held, covariate, method)
    columns = _columns(tests, covariate, method.terms)
    base = base_start(base_fit)
    rows, train_tests = _rows(base, base_fit, tests, held, covariate, columns)
    regression = _Regression(rows, len(columns.labels))
    path, best = _select(regression, columns, method.min_gain_pct)
    index = [columns.labels.index(label) for label in best]
    chosen = tuple(columns.kind[i] for i in index)
    coefficients = np.array([path[best][0][i] for i in index])
    rates = np.array([columns.rate_of[i] for i in index])
    accels = np.array([columns.accel_of[i] for i in index])
    thetas = dict(zip(THETA_FIELDS, coefficients))
    thetas.update(
        {RATE_FIELDS[k]: r for k, r in enumerate(rates) if chosen[k] in MEMORY_TERMS}
    )
    thetas.update({ACCEL_FIELDS[k]: a for k, a in enumerate(accels) if a > 0})
    model = DiscoveredTerm(base, terms=chosen, **thetas) if chosen else base
    result, values = None, coefficients
    stderr = np.full(len(chosen), np.nan)
    if chosen and method.joint_fit:
        assert isinstance(model, DiscoveredTerm)  # terms were chosen
        result = fit_quietly(
            Problem(
                model,
                train_tests,
                fit=[*base_fit_names(base_fit)[0], *model.used_fields()],
                per_test=base_fit_names(base_fit)[1],
                drive=FORCE_DRIVEN.name,
                covariate=covariate,
            ),
            method.least_squares,
        )
        model, values, stderr, rates, accels = _fitted_terms(result, chosen)
    how = force_scoring(tests, covariate)
    base_rmse = how.rmse(base, tests, range(len(tests)), held)
    rmse = how.rmse(model, tests, range(len(tests)), held) if chosen else base_rmse
    return DiscoveryResult(
        terms=chosen,
        coefficients=coefficients,
        model=model,
        fit=result,
        values=values,
        stderr=stderr,
        units=tuple(theta_unit(t, f"[{covariate or 'c'}]") for t in chosen),
        equation=_equation(chosen, values, stderr, covariate, rates, accels),
        rates=rates,
        accels=accels,
        support=tuple(best),
        covariate=covariate,
        heldout_rmse_mm=(base_rmse, rmse),
        gain_pct=100.0 * (1.0 - rmse / base_rmse) if base_rmse > 0 else 0.0,
        path=tuple((s, v[1]) for s, v in path.items()),
    )


def _force_driven(base_fit: FitResult, tests: list, held, covariate, method):
    """`(positions, tests, held)` of the force-driven tests of `base_fit`: the
    discovery's tests and their held-out samples (`held`, else the time split of
    `method.heldout`)."""
    drives = base_fit.drives or (FORCE_DRIVEN,) * len(tests)
    keep = [i for i, d in enumerate(drives) if as_test_drive(d) == FORCE_DRIVEN]
    if not keep:
        raise ValueError(
            "discover runs on force-driven tests; none of `tests` is force-driven."
        )
    tests = [tests[i] for i in keep]
    if held is None:
        fraction = method.heldout.fraction
        held = [
            np.arange(len(t.time)) >= heldout_start(len(t.time), fraction)
            for t in tests
        ]
    else:
        held = [np.asarray(held[i], bool) for i in keep]
    if covariate is not None:
        for i, t in zip(keep, tests):
            if covariate not in (t.extra or {}):
                raise ValueError(
                    f"`tests[{i}]` ({test_id(t, i)}) has no column {covariate!r} "
                    "(the `covariate`)."
                )
    return keep, tests, held


class _Columns(NamedTuple):
    """The regression's columns: the stateless terms `names`, then each term with
    memory at every rate (and acceleration) of its grid (`keys`); `labels` as in
    the path, `kind` the term of each column, `rate_of` and `accel_of` its rate and
    acceleration (NaN for the stateless ones)."""

    names: tuple[str, ...]
    keys: list[tuple[str, float, float]]
    labels: tuple[str, ...]
    kind: list[str]
    rate_of: list[float]
    accel_of: list[float]


def _columns(tests: list, covariate: str | None, terms) -> _Columns:
    """The regression's `_Columns` for `terms` (default: the whole library,
    less the covariate terms without a covariate)."""
    wanted = (
        tuple(terms)
        if terms is not None
        else tuple(
            t
            for t in (*TERMS, *MEMORY_TERMS)
            if covariate is not None or t not in COVARIATE_TERMS
        )
    )
    names = tuple(t for t in wanted if t in TERMS)
    # Each term with memory enters the regression at every rate of its grid (a
    # column per rate; a support holds one rate of a term); the joint fit refines it.
    variation = (
        float(
            np.mean(
                [np.sum(np.abs(np.diff(np.asarray(t.extra[covariate])))) for t in tests]
            )
        )
        if covariate is not None
        else 1.0
    )
    # A damage enters at every acceleration of its grid too, scaled by the largest
    # damage integral of the tests (their recorded loads, not their elongations).
    steps = [step_inputs(t, covariate) for t in tests]
    keys = [
        (t, r, a)
        for t in wanted
        if t in MEMORY_TERMS
        for r in rate_grid(t, variation)
        for a in accel_grid(
            t,
            max(float(damage_integral(x, t, r)[-1]) for x in steps)
            if MEMORY_TERMS[t][3] == "damage"
            else 1.0,
        )
    ]
    labels = names + tuple(
        f"{t}@{r:.3g}" + (f",a={a:.3g}" if a else "") for t, r, a in keys
    )
    return _Columns(
        names,
        keys,
        labels,
        [*names, *(t for t, _, _ in keys)],
        [math.nan] * len(names) + [r for _, r, _ in keys],
        [math.nan] * len(names) + [a for _, _, a in keys],
    )


def _rows(base, base_fit, tests, held, covariate, columns: _Columns):
    """`(rows, train_tests)`: per test, the residual strain, the columns' strains,
    the base's sensitivities (strain), the training and held-out samples and the
    length; and the tests as the joint fit takes them (its training samples those of
    its own mask not held out)."""
    sensitivity = sensitivities(base, base_fit, tests, covariate)
    response = responses(base, tests, FORCE_DRIVEN.name, covariate)
    rows, train_tests = [], []
    for t, m, h, sens in zip(tests, response, held, sensitivity):
        length = float(t.cable().length)
        measured = np.asarray(t.elongation, float)
        own = np.ones(len(m), bool) if t.mask is None else np.asarray(t.mask, bool)
        valid = own & np.isfinite(measured) & np.isfinite(m)
        r = np.where(valid, (measured - m) / length, 0.0)
        lib = library(t, covariate, columns.names)
        lib_memory = memory_library(t, covariate, m / length, columns.keys)
        cum = np.stack(
            [lib[k] for k in columns.names] + [lib_memory[k] for k in columns.keys],
            axis=1,
        ).reshape(len(m), len(columns.labels))
        rows.append((r, cum, sens / length, valid & ~h, valid & h, length))
        train_tests.append(dataclasses.replace(t, mask=~h & own))
    return rows, train_tests


class _Regression:
    """The least squares of the training residual on chosen columns and every base
    sensitivity, scored on the held-out samples."""

    def __init__(self, rows, size: int):
        self.rows, self.size = rows, size

    def solve(self, columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """(theta per column, base step) of the fit on `columns`."""
        x = np.concatenate(
            [
                np.concatenate([c[tr][:, columns], s[tr]], 1)
                for _, c, s, tr, _, _ in self.rows
            ]
        )
        y = np.concatenate([r[tr] for r, _, _, tr, _, _ in self.rows])
        norms = np.linalg.norm(x, axis=0)
        norms = np.where(norms > 0, norms, 1.0)
        z = np.linalg.lstsq(x / norms, y, rcond=None)[0] / norms
        theta = np.zeros(self.size)
        theta[columns] = z[: len(columns)]
        return theta, z[len(columns) :]

    def score(self, theta, step) -> float:
        """The held-out RMSE of what `theta` and `step` leave, mm."""
        sq, n = 0.0, 0
        for r, cum, sens, _, h, length in self.rows:
            sq += float(np.sum(((r - cum @ theta - sens @ step) * length)[h] ** 2))
            n += int(h.sum())
        return 1e3 * math.sqrt(sq / max(n, 1))


def _select(regression: _Regression, columns: _Columns, min_gain_pct: float):
    """`(path, best)`: every support of the forward selection with its `(theta,
    held-out RMSE)`, and the chosen support (empty when none gains `min_gain_pct`
    over no term; of near-equal ones, within 1 %, the fewest terms)."""
    # The base's own parameters move with every support (their sensitivities are
    # columns of every fit): a term the base can mimic by refitting is not a
    # discovery.
    kind, labels = columns.kind, columns.labels
    empty = regression.solve([])
    path: dict[tuple[str, ...], tuple] = {(): (empty[0], regression.score(*empty))}
    support: list[int] = []
    for _ in range(min(MAX_TERMS, len(set(kind)))):
        trials = []
        for k in range(len(labels)):
            if kind[k] in {kind[j] for j in support}:
                continue
            theta, step = regression.solve([*support, k])
            trials.append((regression.score(theta, step), k, theta))
        value, k, theta = min(trials, key=lambda v: v[0])
        support.append(k)
        key = tuple(labels[j] for j in sorted(support))
        path.setdefault(key, (theta, value))
    best = min(path, key=lambda s: path[s][1])
    if path[best][1] > (1 - min_gain_pct / 100) * path[()][1]:
        return path, ()
    near = [s for s in path if path[s][1] <= 1.01 * path[best][1]]
    return path, min(near, key=lambda s: (len(s), path[s][1]))


def _fitted_terms(result: FitResult, chosen: tuple[str, ...]):
    """`(model, values, stderr, rates, accels)` of the chosen terms' joint fit."""
    index = [result.names.index(n) for n in THETA_FIELDS[: len(chosen)]]
    values = np.asarray(result.values, float)[index]
    stderr = np.asarray(result.stderr, float)[index]
    model = result.model
    rates, accels = (
        np.array(
            [
                float(getattr(model, fields[k])) if t in MEMORY_TERMS else math.nan
                for k, t in enumerate(chosen)
            ]
        )
        for fields in (RATE_FIELDS, ACCEL_FIELDS)
    )
    return model, values, stderr, rates, accels


def term_coefficient(base_fit: FitResult, tests, held, covariate: str, term: str):
    """The regression coefficient of one library `term` on the residual of
    `base_fit` (with the base's sensitivities, as the discovery fits it; no joint
    fit), or None when the regression does not keep it or it is not finite.

    **Arguments:**

    - `base_fit`, `tests`, `held`, `covariate`: as in `discover_terms`.
    - `term`: the library term (a key of `TERMS`).

    **Returns:**

    The coefficient, 1/s per unit of the term, or None.
    """
    method = Discovery(terms=(term,), min_gain_pct=-math.inf, joint_fit=False)
    found = discover_terms(base_fit, list(tests), covariate, held, method)
    value = float(found.coefficients[0]) if found.terms else 0.0
    return value if math.isfinite(value) and value != 0.0 else None
