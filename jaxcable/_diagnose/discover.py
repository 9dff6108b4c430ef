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
from typing import Any

import numpy as np

from .._drive import FORCE_DRIVEN, as_test_drive
from .._fit import (
    FitResult,
    as_test_list,
    fit,
    model_responses,
    test_id,
)
from .._models import AbstractCableModel
from .heldout import heldout_start
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
from .scoring import force_scoring


# A support is kept only when its held-out RMSE of the residual is this share below
# that of no term (percent): on noise alone, a term fitted to the training samples
# predicts the held-out ones by chance by at most a few percent.
MIN_GAIN_PCT = 5.0


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
    base_fit: FitResult,
    tests,
    *,
    covariate: str | None = None,
    holdout: float = 0.3,
    held=None,
    terms=None,
    min_gain_pct: float = MIN_GAIN_PCT,
    joint_fit: bool = True,
    **fit_kwargs,
) -> DiscoveryResult:
    """Find at most four library terms whose integrated strain explains the residual
    of a fitted base model, and fit them jointly with the base.

    1. The residual strain r = (measured - model) / L0 of `base_fit`'s model along
        every force-driven test; each library term's strain per unit theta eps_k
        (see [`library`][]); and the sensitivity of the model's strain to each of
        the base's fitted parameters (its Jacobian at the fit).
    2. Forward selection of at most four terms: each support is the least-squares
        fit of r on its terms' strains AND every base sensitivity over the training
        samples (the base's parameters move with every candidate support, so that a
        term the base can mimic by refitting is not chosen), scored by the RMSE of
        what it leaves on the held-out samples.
    3. The support of least held-out RMSE is chosen if it beats no term (the base
        refitted to first order) by `min_gain_pct` (else none), and of near-equal
        ones (within 1 %) the fewest terms.
    4. `DiscoveredTerm(base, theta, terms)` is fitted by [`jaxcable.fit`][]
        (`drive="force"`, the base's fitted parameters and the chosen thetas) on the
        training samples, and scored on the held-out ones.

    **Arguments:**

    - `base_fit`: a [`jaxcable.FitResult`][] of the base model (on the training
        samples of these tests, for an honest held-out score).
    - `tests`: the tests ([`jaxcable.TestData`][]); only force-driven ones are
        used (a test not force-driven in `base_fit` is skipped).
    - `covariate`: an extra column present in every test (its unit is the
        column's), or None: no covariate terms.
    - `holdout`: the held-out fraction at the end of every test (the diagnosis's
        time split), unless `held` is given.
    - `held`: one boolean array per test, True where a sample is held out.
    - `terms`: the library to search (default all of `TERMS`, less the covariate
        terms without a covariate).
    - `min_gain_pct`: the held-out gain over no term a support needs, percent.
    - `joint_fit`: fit the chosen terms with the base (default True).
    - `fit_kwargs`: passed on to [`jaxcable.fit`][] (e.g. `multistart`).

    **Returns:**

    A [`DiscoveryResult`][].

    **Raises:**

    `ValueError` when no test is force-driven, a `terms` id is unknown, or the
    covariate column is missing (naming the test).
    """
    tests = as_test_list(tests)
    drives = getattr(base_fit, "drives", ()) or (FORCE_DRIVEN,) * len(tests)
    keep = [i for i, d in enumerate(drives) if as_test_drive(d) == FORCE_DRIVEN]
    if not keep:
        raise ValueError(
            "discover runs on force-driven tests; none of `tests` is force-driven."
        )
    tests = [tests[i] for i in keep]
    if held is None:
        held = [
            np.arange(len(t.time)) >= heldout_start(len(t.time), holdout) for t in tests
        ]
    else:
        held = [np.asarray(held[i], bool) for i in keep]
    if covariate is not None:
        for i, t in zip(keep, tests):
            if covariate not in (getattr(t, "extra", None) or {}):
                raise ValueError(
                    f"`tests[{i}]` ({test_id(t, i)}) has no column {covariate!r} "
                    "(the `covariate`)."
                )
    wanted = (
        tuple(terms)
        if terms is not None
        else tuple(
            t
            for t in (*TERMS, *MEMORY_TERMS)
            if covariate is not None or t not in COVARIATE_TERMS
        )
    )
    unknown = [t for t in wanted if t not in TERMS and t not in MEMORY_TERMS]
    if unknown:
        raise ValueError(
            f"`terms` {unknown} are not in the library {[*TERMS, *MEMORY_TERMS]}."
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
    kind = [*names, *(t for t, _, _ in keys)]
    rate_of = [math.nan] * len(names) + [r for _, r, _ in keys]
    accel_of = [math.nan] * len(names) + [a for _, _, a in keys]

    base = base_start(base_fit)
    shared, per = base_fit_names(base_fit)
    sensitivity = sensitivities(base, base_fit, tests, covariate)
    response = model_responses(
        base, tests, drive=FORCE_DRIVEN.name, covariate=covariate
    )
    rows, train_tests = [], []
    for t, m, h, sens in zip(tests, response, held, sensitivity):
        length = float(t.cable().length)
        measured = np.asarray(t.elongation, float)
        own = getattr(t, "mask", None)
        own = np.ones(len(m), bool) if own is None else np.asarray(own, bool)
        valid = own & np.isfinite(measured) & np.isfinite(m)
        r = np.where(valid, (measured - m) / length, 0.0)
        lib = library(t, covariate, names)
        lib_memory = memory_library(t, covariate, m / length, keys)
        cum = np.stack(
            [lib[k] for k in names] + [lib_memory[k] for k in keys], axis=1
        ).reshape(len(m), len(labels))
        rows.append((r, cum, sens / length, valid & ~h, valid & h, length))
        # The training samples of the joint fit: those of its own mask not held out.
        train_tests.append(dataclasses.replace(t, mask=~h & own))

    def solve(columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Least squares of the training residual on the chosen terms' strains and
        every base sensitivity: (theta per column of `labels`, base step)."""
        x = np.concatenate(
            [
                np.concatenate([c[tr][:, columns], s[tr]], 1)
                for _, c, s, tr, _, _ in rows
            ]
        )
        y = np.concatenate([r[tr] for r, _, _, tr, _, _ in rows])
        norms = np.linalg.norm(x, axis=0)
        norms = np.where(norms > 0, norms, 1.0)
        z = np.linalg.lstsq(x / norms, y, rcond=None)[0] / norms
        theta = np.zeros(len(labels))
        theta[columns] = z[: len(columns)]
        return theta, z[len(columns) :]

    def score(theta, step) -> float:
        sq, n = 0.0, 0
        for r, cum, sens, _, h, length in rows:
            sq += float(np.sum(((r - cum @ theta - sens @ step) * length)[h] ** 2))
            n += int(h.sum())
        return 1e3 * math.sqrt(sq / max(n, 1))

    # Forward selection, each support scored on the held-out samples. The base's
    # own parameters move with every support (their sensitivities are columns of
    # every fit): a term the base can mimic by refitting is not a discovery.
    empty = solve([])
    path = {(): (empty[0], score(*empty))}
    support: list[int] = []
    for _ in range(min(MAX_TERMS, len(set(kind)))):
        trials = []
        for k in range(len(labels)):
            if kind[k] in {kind[j] for j in support}:
                continue
            theta, step = solve([*support, k])
            trials.append((score(theta, step), k, theta))
        value, k, theta = min(trials, key=lambda v: v[0])
        support.append(k)
        key = tuple(labels[j] for j in sorted(support))
        path.setdefault(key, (theta, value))
    empty_score = path[()][1]
    best = min(path, key=lambda s: path[s][1])
    if path[best][1] > (1 - min_gain_pct / 100) * empty_score:
        best = ()
    else:
        near = [s for s in path if path[s][1] <= 1.01 * path[best][1]]
        best = min(near, key=lambda s: (len(s), path[s][1]))
    coef = path[best][0]
    index = [labels.index(label) for label in best]
    chosen = tuple(kind[i] for i in index)
    coefficients = np.array([coef[i] for i in index])
    rates = np.array([rate_of[i] for i in index])
    accels = np.array([accel_of[i] for i in index])
    units = tuple(theta_unit(t, f"[{covariate or 'c'}]") for t in chosen)
    report_path = tuple((s, v[1]) for s, v in path.items())

    thetas = dict(zip(THETA_FIELDS, coefficients))
    thetas.update(
        {RATE_FIELDS[k]: r for k, r in enumerate(rates) if chosen[k] in MEMORY_TERMS}
    )
    thetas.update({ACCEL_FIELDS[k]: a for k, a in enumerate(accels) if a > 0})
    model = DiscoveredTerm(base, terms=chosen, **thetas) if chosen else base
    result, values = None, coefficients
    stderr = np.full(len(chosen), np.nan)
    if chosen and joint_fit:
        options = {"multistart": 1, "throw": False, **fit_kwargs}
        result = fit(
            model,
            train_tests,
            fit=[*shared, *model.used_fields()],
            per_test=per or None,
            drive=FORCE_DRIVEN.name,
            covariate=covariate,
            **options,
        )
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
        units=units,
        equation=_equation(chosen, values, stderr, covariate, rates, accels),
        rates=rates,
        accels=accels,
        support=tuple(best),
        covariate=covariate,
        heldout_rmse_mm=(base_rmse, rmse),
        gain_pct=100.0 * (1.0 - rmse / base_rmse) if base_rmse > 0 else 0.0,
        path=report_path,
    )


def term_coefficient(base_fit: FitResult, tests, held, covariate: str, term: str):
    """The regression coefficient of one library `term` on the residual of
    `base_fit` (with the base's sensitivities, as the discovery fits it; no joint
    fit), or None when the regression does not keep it or it is not finite.

    **Arguments:**

    - `base_fit`, `tests`, `held`, `covariate`: as in [`jaxcable.discover`][].
    - `term`: the library term (a key of `TERMS`).

    **Returns:**

    The coefficient, 1/s per unit of the term, or None.
    """
    found = discover(
        base_fit,
        tests,
        covariate=covariate,
        held=held,
        terms=(term,),
        min_gain_pct=-math.inf,
        joint_fit=False,
    )
    value = float(found.coefficients[0]) if found.terms else 0.0
    return value if math.isfinite(value) and value != 0.0 else None
