"""What the simulation gets wrong (issue 4): residual structure, candidate extensions
scored on held-out data, the named physical cause and its size.

The workflow of [`jaxcable.diagnose`][]:

1. split every test into a training part and a held-out part (a blocked time split:
   the last `holdout` fraction of each test's samples; or leave-one-test-out);
2. fit the base model on the training parts; its residuals on the whole of every test
   are analysed for structure (against time under load, force, loading vs unloading,
   cycle number, rest time, cable length, rate, temperature, elapsed time; lag-1
   autocorrelation against the white-noise band);
3. fit every candidate extension ([`jaxcable.EXTENSIONS`][]) wrapped around the
   fitted base (warm start: the base's fitted values plus the extension's start
   values; the base's parameters are refitted with the extension's);
4. score each by its held-out RMSE (the gain over the base's, %), by the Bayesian
   information criterion on the training parts (ΔBIC against the base), and by the
   evidence that its size parameter is not zero (|size| / standard error);
5. name the cause: among the candidates significant on all three counts, the one of
   largest held-out gain; `"none"` when none is.
"""

import dataclasses
import json
import math
import pathlib
import warnings
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from .._fit import FitResult, IdentifiabilityWarning, as_test_list, fit, test_id
from .._models import EXTENSIONS, AbstractCableModel, IntegratedModel
from .._report import _grid, _time_axis, model_elongations


# The base parameters refitted by default. Park's hardening (beta, gamma) and the
# long-term retardation law (lambda1, lambda2) are nearly degenerate on cyclic tests
# (correlations > 0.999, a near-zero singular value), so a fit with all twelve free
# wanders along a flat valley; they keep their start values unless `fit=` says more.
DEFAULT_FIT: dict[type, tuple[str, ...]] = {
    IntegratedModel: ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r"),
}

# Significance thresholds of a candidate (see `diagnose`).
MIN_GAIN_PCT = 5.0
MAX_DELTA_BIC = -10.0
MIN_SIZE_Z = 3.0
# Nothing is named while the base already predicts the held-out data to within 20 % of
# the noise level estimated from the data: what is left is noise, and a candidate that
# "explains" it is fitting the noise's realisation (measured: a 10 J/mol activation
# energy, 0.03 % of time scaling, took 9 % off a base held-out RMSE of 1.1 x noise).
MIN_EXCESS = 1.2


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One candidate extension, fitted and scored.

    **Fields:**

    - `id`: the extension's id (a key of [`jaxcable.EXTENSIONS`][]).
    - `heldout_rmse_mm`: RMSE on the held-out samples, mm.
    - `gain_pct`: 100 (base - candidate) / base held-out RMSE, %.
    - `train_rmse_mm`: RMSE on the training samples, mm.
    - `delta_bic`: BIC(candidate) - BIC(base) on the training samples (< 0 favours
        the candidate; -10 is "very strong" evidence).
    - `size`, `size_stderr`, `size_unit`, `size_name`: the effect's size parameter
        (`SIZE_FIELD` of the extension), its standard error and unit.
    - `significant`: gain >= `min_gain_pct`, ΔBIC <= `max_delta_bic` and
        |size| >= `min_size_z` standard errors.
    - `applicable`: False when the data cannot show this effect at all (e.g.
        `temperature` on tests that all ran at one temperature); `note` says why.
    - `fit`: the [`jaxcable.FitResult`][] (None when not applicable).
    """

    id: str
    heldout_rmse_mm: float
    gain_pct: float
    train_rmse_mm: float
    delta_bic: float
    size: float
    size_stderr: float
    size_unit: str
    size_name: str
    significant: bool
    applicable: bool = True
    note: str = ""
    fit: FitResult | None = dataclasses.field(default=None, repr=False, compare=False)

    @classmethod
    def not_applicable(cls, id: str, extension: type, note: str) -> "Candidate":
        """A candidate the data cannot show (`note` says why): no fit, no scores."""
        nan = math.nan
        return cls(
            id,
            nan,
            nan,
            nan,
            nan,
            nan,
            nan,
            extension.SIZE_UNIT,
            extension.SIZE_FIELD,
            significant=False,
            applicable=False,
            note=note,
        )

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out.pop("fit")
        return {k: _jsonable(v) for k, v in out.items()}


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """The result of [`jaxcable.diagnose`][].

    **Fields:**

    - `base_model`: the base model's class name.
    - `named_cause`: the id of the named extension, or `"none"`.
    - `base_heldout_rmse_mm`, `base_train_rmse_mm`: the base model's RMSE, mm.
    - `extended_heldout_rmse_mm`: the held-out RMSE of the named extension (the
        base's when `"none"`), mm.
    - `gain_pct`: its held-out gain, % (0 for `"none"`).
    - `effect`: the named effect's size: `{"parameter", "value", "stderr", "unit"}`
        (empty for `"none"`).
    - `candidates`: every [`jaxcable.Candidate`][], in the order of
        [`jaxcable.EXTENSIONS`][].
    - `structure`: the base residuals' structure: `{feature: correlation}` and the
        lag-1 autocorrelation with its white-noise band (`residual_structure`).
    - `noise_mm`: the elongation noise estimated from the data (robust, from second
        differences), mm.
    - `split`: how held-out data were chosen.
    - `holdout`: the held-out fraction of every test for the time split, None for
        cross-validation by tests.
    - `test_ids`: the tests.
    - `base_fit`: the base model's [`jaxcable.FitResult`][] on the training data.
    """

    base_model: str
    named_cause: str
    base_heldout_rmse_mm: float
    base_train_rmse_mm: float
    extended_heldout_rmse_mm: float
    gain_pct: float
    effect: dict[str, Any]
    candidates: tuple[Candidate, ...]
    structure: dict[str, Any]
    noise_mm: float
    split: str
    holdout: float | None
    test_ids: tuple[str, ...]
    base_fit: FitResult = dataclasses.field(repr=False, compare=False)

    def candidate(self, id: str) -> Candidate:
        """The candidate of this id."""
        for c in self.candidates:
            if c.id == id:
                return c
        raise ValueError(f"`id` {id!r} is not a candidate here.")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (the `--json` output of `jaxcable diagnose`)."""
        return {
            "named_cause": self.named_cause,
            "base_model": self.base_model,
            "base_heldout_rmse_mm": _jsonable(self.base_heldout_rmse_mm),
            "base_train_rmse_mm": _jsonable(self.base_train_rmse_mm),
            "extended_heldout_rmse_mm": _jsonable(self.extended_heldout_rmse_mm),
            "gain_pct": _jsonable(self.gain_pct),
            "effect": {k: _jsonable(v) for k, v in self.effect.items()},
            "noise_mm": _jsonable(self.noise_mm),
            "split": self.split,
            "thresholds": {
                "min_gain_pct": MIN_GAIN_PCT,
                "max_delta_bic": MAX_DELTA_BIC,
                "min_size_z": MIN_SIZE_Z,
                "min_excess_over_noise": MIN_EXCESS,
            },
            "candidates": [c.to_dict() for c in self.candidates],
            "structure": _jsonable(self.structure),
            "tests": list(self.test_ids),
        }

    def to_json(self, path=None) -> str:
        """The diagnosis as JSON text (written to `path` when given)."""
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            pathlib.Path(path).write_text(text + "\n", encoding="utf-8")
        return text

    def summary(self) -> str:
        """A plain-text table: base, every candidate, the named cause."""
        lines = [
            f"jaxcable diagnose: base {self.base_model}, {len(self.test_ids)} test(s), "
            f"held out: {self.split}",
            f"noise (estimated from the data) {self.noise_mm * 1e3:.3g} um; base "
            f"RMSE {self.base_train_rmse_mm:.4g} mm fitted, "
            f"{self.base_heldout_rmse_mm:.4g} mm held out",
            "",
            f"{'candidate':<24}{'held-out mm':>12}{'gain %':>9}{'dBIC':>10}"
            f"{'size':>12}{'+-':>10}  unit",
        ]
        for c in self.candidates:
            if not c.applicable:
                lines.append(f"{c.id:<24}{'n/a':>12}  {c.note}")
                continue
            mark = " *" if c.significant else ""
            lines.append(
                f"{c.id:<24}{c.heldout_rmse_mm:>12.4g}{c.gain_pct:>9.1f}"
                f"{c.delta_bic:>10.1f}{c.size:>12.4g}{c.size_stderr:>10.2g}  "
                f"{c.size_unit}{mark}"
            )
        lines.append("")
        if self.named_cause == "none" and (
            self.base_heldout_rmse_mm <= MIN_EXCESS * self.noise_mm
        ):
            lines.append(
                f"named cause: none (the base predicts the held-out data to within "
                f"{MIN_EXCESS:g} x the noise: {self.base_heldout_rmse_mm * 1e3:.3g} "
                f"um against {self.noise_mm * 1e3:.3g} um)"
            )
        elif self.named_cause == "none":
            lines.append(
                "named cause: none (no candidate improves the held-out RMSE "
                f"significantly: gain >= {MIN_GAIN_PCT:g} %, dBIC <= "
                f"{MAX_DELTA_BIC:g}, size >= {MIN_SIZE_Z:g} standard errors)"
            )
        else:
            e = self.effect
            lines.append(
                f"named cause: {self.named_cause}: {e['parameter']} = "
                f"{e['value']:.4g} +- {e['stderr']:.2g} {e['unit']}; held-out RMSE "
                f"{self.base_heldout_rmse_mm:.4g} -> "
                f"{self.extended_heldout_rmse_mm:.4g} mm ({self.gain_pct:.1f} % gain)"
            )
        strongest = self.structure.get("strongest")
        if strongest:
            lines.append(
                f"base residuals relate most to: {strongest} "
                f"(r = {self.structure['correlation'][strongest]:.2f}); lag-1 "
                f"autocorrelation {self.structure['autocorrelation']:.2f} (white "
                f"noise: |r| < {self.structure['white_noise_band']:.2g})"
            )
        return "\n".join(lines)


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    return x


# ----------------------------------------------------------------------------------
# Held-out splits


def _with_mask(test, mask: np.ndarray):
    own = getattr(test, "mask", None)
    if own is not None:
        mask = mask & np.asarray(own, bool)
    return dataclasses.replace(test, mask=mask)


def _cut(n: int, holdout: float) -> int:
    """The first held-out sample of an `n`-sample test."""
    return int(round(n * (1.0 - holdout)))


def _time_split(tests, holdout: float) -> tuple[list, list]:
    """(training tests, held-out tests): the same tests with complementary masks, the
    last `holdout` fraction of each test's samples held out. The whole history still
    drives the model; only the residuals are split."""
    train, held = [], []
    for test in tests:
        n = len(test.time)
        first = np.arange(n) < _cut(n, holdout)
        train.append(_with_mask(test, first))
        held.append(_with_mask(test, ~first))
    return train, held


def heldout_rmse(
    model: AbstractCableModel,
    tests,
    *,
    holdout: float = 0.3,
) -> float:
    """The RMSE of a given model on the held-out samples of `diagnose`'s time split
    (the last `holdout` fraction of every test), mm.

    For the data-generating model of synthetic data this is the floor no fitted model
    can beat: the elongation noise plus the response to the force noise the model is
    driven with. The hidden-effect tests compare the named model against it.

    **Arguments:**

    - `model`: the model, with its parameters.
    - `tests`: the tests ([`jaxcable.TestData`][]).
    - `holdout`: the held-out fraction of every test.

    **Returns:**

    The pooled RMSE over all held-out samples, mm.
    """
    tests = as_test_list(tests)
    _, held = _time_split(tests, holdout)
    e = model_elongations(model, held)
    sq = sum(float(np.sum((x - t.elongation)[t.mask] ** 2)) for t, x in zip(held, e))
    n = sum(int(np.sum(t.mask)) for t in held)
    return 1e3 * math.sqrt(sq / n)


def noise_level(tests) -> float:
    """A robust estimate of the elongation noise, m: the median absolute second
    difference of each test's elongation, / 0.6745 / sqrt(6) (for white noise the
    second difference has variance 6 sigma^2; the signal's own curvature between
    dense samples is far smaller and the median ignores the reversals), the median
    over tests."""
    values = []
    for t in as_test_list(tests):
        e = np.asarray(t.elongation, float)
        if e.size >= 5:
            d2 = np.diff(e, 2)
            values.append(np.median(np.abs(d2)) / 0.6745 / math.sqrt(6.0))
    return float(np.median(values)) if values else float("nan")


# ----------------------------------------------------------------------------------
# Residual structure


def _features(test) -> dict[str, np.ndarray]:
    """Per-sample explanatory variables of a residual, from the test's own record."""
    time = np.asarray(test.time, float)
    force = np.asarray(test.force, float)
    n = time.size
    loaded = force > 0.05 * max(float(force.max()), 1e-12)
    dt = np.diff(time, prepend=time[0])
    under_load = np.cumsum(np.where(loaded, dt, 0.0))
    # Time since the force last was loaded (0 while loaded): the rest time.
    last = np.maximum.accumulate(np.where(loaded, np.arange(n), -1))
    rest = np.where(last >= 0, time - time[np.maximum(last, 0)], time - time[0])
    # Cycle number: upward crossings of half the peak force so far.
    up = (force[1:] >= 0.5 * force.max()) & (force[:-1] < 0.5 * force.max())
    cycle = np.concatenate([[0], np.cumsum(up)])
    slope = np.gradient(force, time) if n > 1 else np.zeros(n)
    scale = np.median(np.abs(slope[slope != 0])) if np.any(slope != 0) else 1.0
    branch = np.where(slope > 0.1 * scale, 1.0, np.where(slope < -0.1 * scale, -1, 0))
    cable = test.cable()
    out = {
        "time under load": under_load,
        "force": force,
        "loading vs unloading": branch,
        "cycle number": cycle.astype(float),
        "rest time": rest,
        "cable length": np.full(n, float(cable.length)),
        "rate": np.full(n, float(cable.speed)),
        "elapsed time": time - time[0],
    }
    if getattr(test, "temperature", None) is not None:
        out["temperature"] = np.asarray(test.temperature, float)
    return out


def residual_structure(tests, residual: Sequence[np.ndarray]) -> dict[str, Any]:
    """How the residuals of a fit depend on the test conditions.

    **Arguments:**

    - `tests`: the tests ([`jaxcable.TestData`][]), their masks marking the samples
        to use.
    - `residual`: model minus measured elongation of each test, m.

    **Returns:**

    `{"correlation": {feature: Pearson r of residual and feature over all samples},
    "strongest": the feature of largest |r|, "autocorrelation": pooled lag-1
    autocorrelation of the residuals, "white_noise_band": 1.96 / sqrt(n), "mean_mm":
    {"loading", "unloading", "hold"}: mean residual on each branch, mm}`. Features
    constant over the data (one length, one temperature) have no correlation (None).
    """
    tests = as_test_list(tests)
    columns: dict[str, list] = {}
    rs, lag = [], []
    for test, r in zip(tests, residual):
        r = np.asarray(r, float)
        own = getattr(test, "mask", None)
        mask = np.ones(r.shape, bool) if own is None else np.asarray(own, bool)
        keep = mask & np.isfinite(r)
        for name, values in _features(test).items():
            columns.setdefault(name, [])
            columns[name].append(values[keep])
        rs.append(r[keep])
        rc = r[keep] - r[keep].mean() if keep.any() else r[keep]
        if rc.size > 2:
            lag.append((rc[1:] * rc[:-1]).sum() / max((rc * rc).sum(), 1e-300))
    r_all = np.concatenate(rs)
    correlation = {}
    for name, parts in columns.items():
        if len(parts) != len(rs):  # a feature some tests lack (temperature)
            continue
        x = np.concatenate(parts)
        if x.size < 3 or np.ptp(x) <= 1e-12 * max(np.abs(x).max(), 1e-300):
            correlation[name] = None
            continue
        correlation[name] = float(np.corrcoef(x, r_all)[0, 1])
    valid = {k: abs(v) for k, v in correlation.items() if v is not None}
    branch = np.concatenate(columns["loading vs unloading"])
    mean_mm = {
        label: float(1e3 * r_all[branch == b].mean()) if np.any(branch == b) else None
        for label, b in (("loading", 1), ("unloading", -1), ("hold", 0))
    }
    return {
        "correlation": correlation,
        "strongest": max(valid, key=valid.get) if valid else None,
        "autocorrelation": float(np.mean(lag)) if lag else float("nan"),
        "white_noise_band": 1.96 / math.sqrt(max(r_all.size, 1)),
        "mean_mm": mean_mm,
    }


# ----------------------------------------------------------------------------------
# The workflow


def _bic(rmse_mm: float, n: int, p: int) -> float:
    return n * math.log(max((rmse_mm * 1e-3) ** 2, 1e-300)) + p * math.log(n)


def _applicability(ext_id: str, tests) -> str:
    """Why the data cannot show an effect at all, or "" when they can."""
    if ext_id == "temperature":
        temps = [
            np.asarray(t.temperature, float)
            for t in tests
            if getattr(t, "temperature", None) is not None
        ]
        if len(temps) < len(tests):
            return "not every test records its temperature"
        span = float(np.ptp(np.concatenate(temps)))
        if span < 2.0:
            return f"the tests span {span:.2g} K: no temperature contrast"
    return ""


def _default_fit_names(model: AbstractCableModel) -> tuple[str, ...] | None:
    return DEFAULT_FIT.get(type(model))


def diagnose(
    tests,
    model: AbstractCableModel | None = None,
    *,
    fit_names: Sequence[str] | None = None,
    candidates: Sequence[str] | None = None,
    split: Literal["time", "tests"] = "time",
    holdout: float = 0.3,
    folds: int | None = None,
    multistart: int = 1,
    max_steps: int = 256,
    key=None,
    progress=None,
) -> Diagnosis:
    """Find what a model gets wrong on measured data and name the physical cause.

    See the module's description of the workflow (`jaxcable._diagnose`). A candidate
    is significant when (1) its held-out RMSE is at least `MIN_GAIN_PCT` = 5 % below
    the base's, (2) ΔBIC = BIC(candidate) - BIC(base) <= -10 on the training samples
    (BIC = n ln(SSR/n) + p ln n), and (3) its size parameter is at least
    `MIN_SIZE_Z` = 3 standard errors from zero. The named cause is the significant
    candidate of largest held-out gain, else `"none"`; and `"none"` whenever the base
    model's held-out RMSE is within `MIN_EXCESS` = 1.2 times the noise level estimated
    from the data ([`noise_level`][]): there is nothing left to explain.

    **Arguments:**

    - `tests`: the measured tests ([`jaxcable.TestData`][] with elongation).
    - `model`: the base model and its start values (default
        [`jaxcable.IntegratedModel`][] with its defaults).
    - `fit_names`: the base parameters to fit (default: for the integrated model
        the eight of `DEFAULT_FIT`, else all).
    - `candidates`: extension ids to try (default: all of [`jaxcable.EXTENSIONS`][]).
    - `split`: `"time"`: a blocked time split, the last `holdout` fraction of every
        test's samples held out (the model still runs through them; they are not
        fitted). `"tests"`: k-fold cross-validation over whole tests (test i is in
        fold i mod k; one fit per fold and candidate; needs at least two tests).
    - `holdout`: the held-out fraction for `split="time"`, in (0, 0.9].
    - `folds`: k for `split="tests"` (default: one fold per test, leave-one-out).
    - `multistart`: starts of the base fit (the candidates start from it).
    - `max_steps`: Levenberg-Marquardt steps per fit.
    - `key`: PRNG key of the multistart perturbations.
    - `progress`: an optional callable `progress(message: str)` told of each fit.

    **Returns:**

    A [`jaxcable.Diagnosis`][].

    **Raises:**

    `ValueError` naming the argument: an unknown candidate id, a bad `split` or
    `holdout`, too few tests for leave-one-test-out; and the errors of
    [`jaxcable.fit`][] for bad data.
    """
    tests = as_test_list(tests)
    if model is None:
        model = IntegratedModel()
    if not isinstance(model, AbstractCableModel):
        raise ValueError(
            f"`model` must be a jaxcable model, got {type(model).__name__}."
        )
    ids = list(EXTENSIONS) if candidates is None else list(candidates)
    unknown = [c for c in ids if c not in EXTENSIONS]
    if unknown:
        raise ValueError(
            f"`candidates` names {unknown}; known extensions: {list(EXTENSIONS)}."
        )
    if split not in ("time", "tests"):
        raise ValueError(f"`split` must be 'time' or 'tests', got {split!r}.")
    if not (isinstance(holdout, (int, float)) and 0.0 < holdout <= 0.9):
        raise ValueError(f"`holdout` must be in (0, 0.9], got {holdout!r}.")
    if split == "tests" and len(tests) < 2:
        raise ValueError(
            "`split='tests'` (cross-validation by tests) needs >= 2 tests."
        )
    k = len(tests) if folds is None else folds
    if split == "tests" and not (isinstance(k, int) and 2 <= k <= len(tests)):
        raise ValueError(f"`folds` must be an int in [2, {len(tests)}], got {folds!r}.")
    for i, t in enumerate(tests):
        if getattr(t, "elongation", None) is None:
            raise ValueError(
                f"`tests[{i}]` ({test_id(t, i)}) has no elongation to diagnose."
            )
    tests = [
        t
        if getattr(t, "mask", None) is not None
        else _with_mask(t, np.ones(len(t.time), bool))
        for t in tests
    ]
    names = tuple(fit_names) if fit_names is not None else _default_fit_names(model)
    say = progress or (lambda message: None)

    def run_fit(m, train, fitted, starts):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IdentifiabilityWarning)
            return fit(
                m,
                train,
                fit=fitted,
                multistart=starts,
                max_steps=max_steps,
                key=key,
                throw=False,
            )

    def folds():
        if split == "time":
            train, held = _time_split(tests, holdout)
            yield train, held, list(range(len(tests)))
        else:
            for fold in range(k):
                train = [t for i, t in enumerate(tests) if i % k != fold]
                held = [t for i, t in enumerate(tests) if i % k == fold]
                yield train, held, [i for i in range(len(tests)) if i % k == fold]

    def score(start_models, fitted, starts, base_losses=None):
        """(held-out RMSE mm, train RMSE mm, n_train, the fit of every fold).

        `start_models(k)` gives fold k's start models: the first is fitted; when its
        training SSR is above the base model's on that fold (`base_losses`), the
        second is fitted too and the better kept, so that a candidate never fits
        its training data worse than the base it contains."""
        sq_held = n_held = sq_train = n_train = 0.0
        results = []
        for k, (train, held, _) in enumerate(folds()):
            first, *others = start_models(k)
            result = run_fit(first, train, fitted, starts)
            if (
                base_losses is not None
                and others
                and not (result.loss <= base_losses[k])
            ):
                other = run_fit(others[0], train, fitted, starts)
                if not (result.loss <= other.loss):
                    result = other
            results.append(result)
            if not math.isfinite(result.loss):
                return math.inf, math.inf, 1, results
            e_train = model_elongations(result, train)
            # Shared parameters only, so the fitted model runs on any test.
            e_held = e_train if split == "time" else model_elongations(result, held)
            for t, e in zip(train, e_train):
                m = np.asarray(t.mask, bool)
                sq_train += float(np.sum((e - t.elongation)[m] ** 2))
                n_train += int(m.sum())
            for t, e in zip(held, e_held):
                m = np.asarray(t.mask, bool)
                sq_held += float(np.sum((e - t.elongation)[m] ** 2))
                n_held += int(m.sum())
        return (
            1e3 * math.sqrt(sq_held / max(n_held, 1)),
            1e3 * math.sqrt(sq_train / max(n_train, 1)),
            int(n_train),
            results,
        )

    say(f"fitting the base model {type(model).__name__}")
    base_held, base_train, n_train, base_folds = score(
        lambda k: [model], names, multistart
    )
    base_fit = base_folds[0]
    base_losses = [r.loss for r in base_folds]
    if not math.isfinite(base_held):
        raise RuntimeError(
            f"jaxcable.diagnose: the base model's fit failed ({base_fit.message})."
        )
    p_base = len(base_fit.names)
    bic_base = _bic(base_train, n_train, p_base)
    # The candidates refit the base's fitted parameters (all of them when `names` is
    # None) plus their own effect fields, never the extension's fixed ones.
    base_names = base_fit.names

    # The base's residuals over whole tests, for the structure analysis.
    whole = model_elongations(base_fit, tests)
    structure = residual_structure(
        tests, [e - t.elongation for t, e in zip(tests, whole)]
    )

    out = []
    for ext_id in ids:
        cls = EXTENSIONS[ext_id]
        reason = _applicability(ext_id, tests)
        if not reason:
            try:
                # From the user's start (not the base fit, which has absorbed part
                # of the effect into the base's parameters and is often a local
                # minimum for the extended model), then from the base fit when that
                # fits the training data worse than the base did.
                starts = [cls.wrap(model), *(cls.wrap(r.model) for r in base_folds)]
            except ValueError as e:
                reason = str(e)
        if reason:
            out.append(Candidate.not_applicable(ext_id, cls, reason))
            continue
        say(f"fitting candidate {ext_id}")
        fitted = tuple("base." + n for n in base_names) + tuple(cls.EFFECT_FIELDS)
        held, train_rmse, n, fold_fits = score(
            lambda k: [starts[0], starts[1 + k]], fitted, 1, base_losses
        )
        result = fold_fits[0]
        p = len(result.names)
        size_index = result.names.index(cls.SIZE_FIELD)
        size = float(result.values[size_index])
        stderr = float(result.stderr[size_index])
        gain = 100.0 * (base_held - held) / base_held
        delta_bic = _bic(train_rmse, n, p) - bic_base
        z = abs(size) / stderr if stderr > 0 else (math.inf if size != 0 else 0.0)
        significant = bool(
            math.isfinite(held)
            and gain >= MIN_GAIN_PCT
            and delta_bic <= MAX_DELTA_BIC
            and z >= MIN_SIZE_Z
        )
        out.append(
            Candidate(
                ext_id,
                held,
                gain,
                train_rmse,
                delta_bic,
                size,
                stderr,
                cls.SIZE_UNIT,
                cls.SIZE_FIELD,
                significant,
                True,
                "",
                result,
            )
        )

    noise_mm = 1e3 * noise_level(tests)
    winners = [c for c in out if c.significant]
    if winners and base_held > MIN_EXCESS * noise_mm:
        best = max(winners, key=lambda c: c.gain_pct)
        named, extended, gain = best.id, best.heldout_rmse_mm, best.gain_pct
        effect = {
            "parameter": best.size_name,
            "value": best.size,
            "stderr": best.size_stderr,
            "unit": best.size_unit,
        }
    else:
        named, extended, gain, effect = "none", base_held, 0.0, {}
    return Diagnosis(
        base_model=type(model).__name__,
        named_cause=named,
        base_heldout_rmse_mm=base_held,
        base_train_rmse_mm=base_train,
        extended_heldout_rmse_mm=extended,
        gain_pct=gain,
        effect=effect,
        candidates=tuple(out),
        structure=structure,
        noise_mm=noise_mm,
        split=(
            f"last {holdout:.0%} of every test's samples"
            if split == "time"
            else "leave-one-test-out"
            if k == len(tests)
            else f"{k}-fold by tests"
        ),
        holdout=holdout if split == "time" else None,
        test_ids=tuple(test_id(t, i) for i, t in enumerate(tests)),
        base_fit=base_fit,
    )


# ----------------------------------------------------------------------------------
# Report


def write_diagnosis_report(out, diagnosis: Diagnosis, tests) -> list[pathlib.Path]:
    """Write the diagnosis report to the folder `out` (created if needed).

    Files: `diagnosis.json` ([`jaxcable.Diagnosis.to_json`][]), `summary.md`,
    `residuals.png` (model minus measured elongation vs time, base and the named
    extension, before/after, held-out part shaded), `candidates.png` (held-out gain
    of every candidate against the threshold) and `structure.png` (correlation of the
    base residuals with each test condition).

    **Returns:**

    The paths written.
    """
    from matplotlib.figure import Figure

    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tests = as_test_list(tests)
    whole = [dataclasses.replace(t, mask=None) for t in tests]
    base = model_elongations(diagnosis.base_fit, whole)
    named = (
        diagnosis.candidate(diagnosis.named_cause)
        if diagnosis.named_cause != "none"
        else None
    )
    extended = model_elongations(named.fit, whole) if named is not None else None

    rows, cols = _grid(len(tests))
    fig = Figure(figsize=(3.8 * cols, 2.7 * rows + 0.8), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for i, t in enumerate(whole):
        ax = axes[i]
        x, label, log = _time_axis(np.asarray(t.time, float))
        ax.plot(x, 1e3 * (base[i] - t.elongation), color="0.5", lw=0.8, label="base")
        if extended is not None:
            ax.plot(
                x,
                1e3 * (extended[i] - t.elongation),
                color="tab:blue",
                lw=0.8,
                label=f"+ {diagnosis.named_cause}",
            )
        if diagnosis.holdout is not None:
            cut = _cut(len(t.time), diagnosis.holdout)
            if cut < len(t.time):
                ax.axvspan(x[cut], x[-1], color="tab:orange", alpha=0.12, lw=0)
        ax.axhline(0.0, color="0.3", lw=0.5)
        ax.set_title(diagnosis.test_ids[i], fontsize=9)
        if log:
            ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("model - measured [mm]")
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=8)
    for ax in axes[len(tests) :]:
        ax.set_visible(False)
    fig.suptitle(
        f"Residuals before/after (held-out part shaded): named cause "
        f"{diagnosis.named_cause}"
    )
    residuals_png = out / "residuals.png"
    fig.savefig(residuals_png, dpi=90)

    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.subplots()
    shown = [c for c in diagnosis.candidates if c.applicable]
    gains = [c.gain_pct if math.isfinite(c.gain_pct) else 0.0 for c in shown]
    colours = ["tab:blue" if c.id == diagnosis.named_cause else "0.6" for c in shown]
    ax.barh([c.id for c in shown], gains, color=colours)
    ax.axvline(MIN_GAIN_PCT, color="tab:red", lw=0.8, ls="--", label="threshold")
    ax.set_xlabel("held-out RMSE gain over the base [%]")
    ax.set_title(
        f"base held-out RMSE {diagnosis.base_heldout_rmse_mm:.3g} mm; named: "
        f"{diagnosis.named_cause}",
        fontsize=10,
    )
    ax.invert_yaxis()
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="x")
    candidates_png = out / "candidates.png"
    fig.savefig(candidates_png, dpi=90)

    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.subplots()
    corr = {
        k: v for k, v in diagnosis.structure["correlation"].items() if v is not None
    }
    ax.barh(list(corr), list(corr.values()), color="tab:purple")
    ax.axvline(0, color="0.3", lw=0.5)
    ax.set_xlim(-1, 1)
    ax.set_xlabel("correlation of the base residual with the condition")
    ax.set_title(
        f"lag-1 autocorrelation {diagnosis.structure['autocorrelation']:.2f} "
        f"(white noise: < {diagnosis.structure['white_noise_band']:.2g})",
        fontsize=10,
    )
    ax.invert_yaxis()
    ax.grid(alpha=0.3, axis="x")
    structure_png = out / "structure.png"
    fig.savefig(structure_png, dpi=90)

    json_path = out / "diagnosis.json"
    diagnosis.to_json(json_path)
    table = [
        "| candidate | held-out RMSE mm | gain % | ΔBIC | size | ± | unit | significant |",
        "| --- | ---: | ---: | ---: | ---: | ---: | --- | --- |",
    ]
    for c in diagnosis.candidates:
        if not c.applicable:
            table.append(f"| {c.id} | n/a | | | | | | {c.note} |")
            continue
        table.append(
            f"| {c.id} | {c.heldout_rmse_mm:.4g} | {c.gain_pct:.1f} | "
            f"{c.delta_bic:.1f} | {c.size:.4g} | {c.size_stderr:.2g} | "
            f"{c.size_unit} | {'yes' if c.significant else 'no'} |"
        )
    summary = out / "summary.md"
    summary.write_text(
        "# jaxcable diagnose\n\n```\n"
        + diagnosis.summary()
        + "\n```\n\n"
        + "\n".join(table)
        + "\n\n![residuals](residuals.png)\n![candidates](candidates.png)\n"
        + "![structure](structure.png)\n",
        encoding="utf-8",
    )
    return [json_path, summary, residuals_png, candidates_png, structure_png]
