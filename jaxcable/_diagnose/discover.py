"""Discovery of a term the base model lacks: sparse regression of the base's strain
residual on a library of integrated terms ([`jaxcable.DiscoveredTerm`][]) and the
base's own parameter sensitivities, the sparsity chosen on held-out samples, then a joint Levenberg-Marquardt fit of the
base with the chosen terms, reported as an equation with units.

Discovery runs on force-driven tests (the model driven by the measured force, the
elongation scored): the library terms are functions of the force history and the
covariate, which an elongation-driven test does not prescribe.
"""

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._fit import (
    FitResult,
    as_test_list,
    fit,
    make_problem,
    model_responses,
    residuals_and_jacobian,
    test_id,
)
from .._models import AbstractCableModel, discovered
from .heldout import heldout_start, with_mask


MAX_TERMS = discovered.MAX_TERMS
TERMS = discovered.TERMS
THETA_FIELDS = discovered.THETA_FIELDS
DiscoveredTerm = discovered.DiscoveredTerm
cycle_count = discovered.cycle_count
term_increments = discovered.term_increments
theta_unit = discovered.theta_unit
tension_time_step = discovered.tension_time_step

# The terms that read the covariate (left out of the library without one).
COVARIATE_TERMS = ("c", "c_rate", "c_abs_rate", "sigma_c", "sigma_c_abs_rate")

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
        thresholds gave, the empty one first.
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


def library(test, covariate: str | None, names=tuple(TERMS)) -> dict[str, np.ndarray]:
    """Each library term's contribution to the discovered strain per unit theta,
    eps_k(t) (the cumulative sum of [`term_increments`][] along the test, as
    `DiscoveredTerm.advance` integrates it), host-side.

    **Arguments:**

    - `test`: a force-driven test (time s, force N, `cable()`).
    - `covariate`: the extra column read as c, or None (c = 0).
    - `names`: the terms wanted.

    **Returns:**

    `{term: eps_k per sample}` (1/theta_k units: s x unit of phi).
    """
    time = np.asarray(test.time, float)
    force = np.asarray(test.force, float)
    c = np.zeros_like(time)
    if covariate is not None:
        c = np.asarray(test.extra[covariate], float)
    cable = test.cable()
    area = float(cable.area)
    # The first sample is applied from the unloaded cable at time[0] (dt = 0).
    force0 = np.r_[0.0, force[:-1]]
    c0 = np.r_[c[0], c[:-1]]
    dt = np.r_[0.0, np.diff(time)]
    force_max = np.maximum.accumulate(np.maximum(force, 0.0))
    dt_loaded = np.asarray(
        jax.vmap(tension_time_step, in_axes=(0, 0, 0, None, 0))(
            jnp.asarray(force0), jnp.asarray(force), jnp.asarray(dt), cable, force_max
        ),
        float,
    )
    loaded = np.cumsum(dt_loaded)
    rest = np.cumsum(dt - dt_loaded)
    cycles = np.asarray(
        cycle_count(np.cumsum(np.abs(force - force0)), force_max), float
    )

    def before(x):
        return np.r_[0.0, x[:-1]]

    increments = term_increments(
        force0 / area,
        force / area,
        c0,
        c,
        dt,
        before(loaded),
        loaded,
        before(rest),
        rest,
        before(cycles),
        cycles,
    )
    return {k: np.cumsum(np.asarray(increments[k], float)) for k in names}


def base_start(base_fit: FitResult) -> AbstractCableModel:
    """The fitted base as a start model (per-test values averaged to scalars)."""
    return jax.tree_util.tree_map(
        lambda x: jnp.mean(x) if eqx.is_inexact_array(x) and x.ndim else x,
        base_fit.model,
    )


def _equation(terms, values, stderr, covariate) -> str:
    """`d(eps)/dt = v (+-se) unit * symbol + ...` (`0` without terms)."""
    name = covariate or "c"
    parts = []
    for t, v, se in zip(terms, values, stderr):
        symbol = TERMS[t][0].replace("c", name) if t in COVARIATE_TERMS else TERMS[t][0]
        err = f" (+-{se:.2g})" if math.isfinite(se) else ""
        parts.append(f"{v:.3g}{err} {theta_unit(t, f'[{name}]')} * {symbol}")
    return "d(eps)/dt = " + (" + ".join(parts) if parts else "0")


def _sensitivities(base, base_fit: FitResult, tests) -> list[np.ndarray]:
    """d(model elongation)/du of the base's fitted parameters at its fit (u: the
    fit's unconstrained parameters, log for the positive ones), m, one
    `(samples, p)` array per test, every sample."""
    names = list(dict.fromkeys(n.split("[")[0] for n in base_fit.names))
    full = [
        dataclasses.replace(
            t, mask=None, elongation=np.nan_to_num(np.asarray(t.elongation, float))
        )
        for t in tests
    ]
    problem, u = make_problem(base, full, names, None, None, "force")
    _, jacobian = residuals_and_jacobian(problem, u, "fwd")
    jacobian = np.asarray(jacobian).reshape(len(full), -1, u.shape[0])
    return [jacobian[i, : len(t.time)] for i, t in enumerate(full)]


def heldout_rmse_mm(model, tests, held, covariate) -> float:
    """RMSE over the held-out samples each test's own mask keeps (as the
    diagnosis scores), mm."""
    response = model_responses(model, tests, drive="force", covariate=covariate)
    sq, n = 0.0, 0
    for r, t, h in zip(response, tests, held):
        own = getattr(t, "mask", None)
        keep = h if own is None else h & np.asarray(own, bool)
        sq += float(np.sum((r - np.asarray(t.elongation, float))[keep] ** 2))
        n += int(keep.sum())
    return 1e3 * math.sqrt(sq / max(n, 1))


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
        used (a test whose drive in `base_fit` is not `"force"` is skipped).
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
    drives = getattr(base_fit, "drives", ()) or ("force",) * len(tests)
    keep = [i for i, d in enumerate(drives) if d == "force"]
    if not keep:
        raise ValueError(
            "discover runs on force-driven tests; none of `tests` is force-driven."
        )
    tests = [tests[i] for i in keep]
    if held is None:
        held = []
        for t in tests:
            n = len(t.time)
            held.append(np.arange(n) >= heldout_start(n, holdout))
    else:
        held = [np.asarray(held[i], bool) for i in keep]
    if covariate is not None:
        for i, t in zip(keep, tests):
            if covariate not in (getattr(t, "extra", None) or {}):
                raise ValueError(
                    f"`tests[{i}]` ({test_id(t, i)}) has no column {covariate!r} "
                    "(the `covariate`)."
                )
    names = (
        tuple(terms)
        if terms is not None
        else tuple(
            t for t in TERMS if covariate is not None or t not in COVARIATE_TERMS
        )
    )
    unknown = [t for t in names if t not in TERMS]
    if unknown:
        raise ValueError(f"`terms` {unknown} are not in the library {list(TERMS)}.")

    base = base_start(base_fit)
    response = model_responses(base, tests, drive="force")
    sensitivity = _sensitivities(base, base_fit, tests)
    rows = []
    for t, m, h, sens in zip(tests, response, held, sensitivity):
        length = float(t.cable().length)
        measured = np.asarray(t.elongation, float)
        own = getattr(t, "mask", None)
        own = np.ones(len(m), bool) if own is None else np.asarray(own, bool)
        valid = own & np.isfinite(measured) & np.isfinite(m)
        r = np.where(valid, (measured - m) / length, 0.0)
        lib = library(t, covariate, names)
        cum = np.stack([lib[k] for k in names], axis=1)
        rows.append((r, cum, sens / length, valid & ~h, valid & h, length))

    def solve(columns: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Least squares of the training residual on the chosen terms' strains and
        every base sensitivity: (theta per term of `names`, base parameter step)."""
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
        theta = np.zeros(len(names))
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
    for _ in range(min(MAX_TERMS, len(names))):
        trials = []
        for k in range(len(names)):
            if k in support:
                continue
            theta, step = solve([*support, k])
            trials.append((score(theta, step), k, theta))
        value, k, theta = min(trials, key=lambda v: v[0])
        support.append(k)
        key = tuple(names[j] for j in sorted(support))
        path.setdefault(key, (theta, value))
    empty_score = path[()][1]
    best = min(path, key=lambda s: path[s][1])
    if path[best][1] > (1 - min_gain_pct / 100) * empty_score:
        best = ()
    else:
        near = [s for s in path if path[s][1] <= 1.01 * path[best][1]]
        best = min(near, key=lambda s: (len(s), path[s][1]))
    coef = path[best][0]
    chosen = tuple(best)
    coefficients = np.array([coef[names.index(t)] for t in chosen])
    units = tuple(theta_unit(t, f"[{covariate or 'c'}]") for t in chosen)
    report_path = tuple((s, v[1]) for s, v in path.items())

    thetas = dict(zip(THETA_FIELDS, coefficients))
    model = DiscoveredTerm(base, terms=chosen, **thetas) if chosen else base
    base_rmse = heldout_rmse_mm(base, tests, held, None)
    result, values = None, coefficients
    stderr = np.full(len(chosen), np.nan)
    if chosen and joint_fit:
        base_names = [n.split("[")[0] for n in base_fit.names]
        fitted = list(dict.fromkeys("base." + n for n in base_names))
        per = ["base." + n for n in getattr(base_fit, "per_test", ())]
        fitted += list(model.used_fields())
        train_tests = [with_mask(t, ~h) for t, h in zip(tests, held)]
        options = {"multistart": 1, "throw": False, **fit_kwargs}
        result = fit(
            model,
            train_tests,
            fit=[n for n in fitted if n not in per],
            per_test=per or None,
            drive="force",
            covariate=covariate,
            **options,
        )
        index = [result.names.index(n) for n in model.used_fields()]
        values = np.asarray(result.values, float)[index]
        stderr = np.asarray(result.stderr, float)[index]
        model = result.model
    rmse = heldout_rmse_mm(model, tests, held, covariate) if chosen else base_rmse
    return DiscoveryResult(
        terms=chosen,
        coefficients=coefficients,
        model=model,
        fit=result,
        values=values,
        stderr=stderr,
        units=units,
        equation=_equation(chosen, values, stderr, covariate),
        covariate=covariate,
        heldout_rmse_mm=(base_rmse, rmse),
        gain_pct=100.0 * (1.0 - rmse / base_rmse) if base_rmse > 0 else 0.0,
        path=report_path,
    )
