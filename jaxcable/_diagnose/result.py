"""The result of a diagnosis: the scored candidate extensions (`Candidate`), the
decision (`Diagnosis`) with its JSON and plain-text forms, and the thresholds that
decide significance."""

import dataclasses
import json
import math
from typing import Any

from .._drive import AbstractTestDrive, as_test_drive
from .._files import write_text_atomic
from .._fit import FitResult
from .._json import jsonable
from .verdict import (
    MAX_FLOOR_RATIO,
    MIN_AUTOCORRELATION,
    MIN_EXCESS,
    MIN_EXPLAINED_PCT,
)


# Significance thresholds of a candidate (see `jaxcable.diagnose`).
MIN_GAIN_PCT = 5.0
MAX_DELTA_BIC = -10.0
MIN_SIZE_Z = 3.0
# MIN_EXCESS, MAX_FLOOR_RATIO and MIN_EXPLAINED_PCT (the verdict): see `verdict.py`.


class _InMm:
    """A read-only attribute: the field `name` (in the object's `unit`) in mm; NaN
    unless `unit` is mm (the mm fields keep meaning mm)."""

    def __init__(self, name: str):
        self.name = name
        self.__doc__ = f"`{name}` in mm (NaN unless `unit` is mm)."

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        return getattr(obj, self.name) if obj.unit == "mm" else math.nan


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One candidate extension, fitted and scored.

    **Fields:**

    - `id`: the extension's id (a key of [`jaxcable.EXTENSIONS`][]).
    - `heldout_rmse`: RMSE on the held-out samples, in `unit`.
    - `gain_pct`: 100 (base - candidate) / base held-out RMSE, %.
    - `train_rmse`: RMSE on the training samples, in `unit`.
    - `delta_bic`: BIC(candidate) - BIC(base) on the training samples (< 0 favours
        the candidate; -10 is "very strong" evidence).
    - `size`, `size_stderr`, `size_unit`, `size_name`: the effect's size parameter
        (`SIZE_FIELD` of the extension), its standard error and unit.
    - `significant`: gain >= `min_gain_pct`, ΔBIC <= `max_delta_bic` and
        |size| >= `min_size_z` standard errors.
    - `applicable`: False when the data cannot show this effect at all (e.g.
        `temperature` on tests that all ran at one temperature); `note` says why.
    - `fit`: the [`jaxcable.FitResult`][] (None when not applicable).
    - `unit`: the unit of the RMSEs: `"mm"` (every test scored in its elongation),
        `"N"` (every test in its force) or `"noise"` (mixed drives: each residual
        divided by the noise of its test's scored channel).
    - `explained_pct`: the share of the base's held-out excess over the noise floor
        this candidate explains, %: 100 (base^2 - candidate^2) / (base^2 -
        floor^2) of the held-out RMSEs (NaN when not applicable or no excess).
    - `heldout_rmse_mm`, `train_rmse_mm` (properties): the RMSEs in mm; NaN unless
        `unit` is mm.
    """

    id: str
    heldout_rmse: float
    gain_pct: float
    train_rmse: float
    delta_bic: float
    size: float
    size_stderr: float
    size_unit: str
    size_name: str
    significant: bool
    applicable: bool = True
    note: str = ""
    fit: FitResult | None = dataclasses.field(default=None, repr=False, compare=False)
    unit: str = "mm"
    explained_pct: float = math.nan

    heldout_rmse_mm = _InMm("heldout_rmse")
    train_rmse_mm = _InMm("train_rmse")

    @classmethod
    def not_applicable(
        cls, id: str, extension: type, note: str, unit: str = "mm"
    ) -> "Candidate":
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
            unit=unit,
        )

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of the scores (the fit left out; NaN as None), with the
        RMSEs in `unit` and, as before, in mm (None unless `unit` is mm)."""
        out = dataclasses.asdict(self)
        out.pop("fit")
        out["heldout_rmse_mm"] = self.heldout_rmse_mm
        out["train_rmse_mm"] = self.train_rmse_mm
        return {k: jsonable(v) for k, v in out.items()}


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """The result of [`jaxcable.diagnose`][].

    **Fields:**

    - `base_model`: the base model's class name.
    - `named_cause`: the id of the named extension, `"none"` (nothing to explain,
        or no candidate significant and no excess), or `"unexplained"` (see
        `verdict`).
    - `base_heldout_rmse`, `base_train_rmse`: the base model's RMSE, in `unit`.
    - `extended_heldout_rmse`: the held-out RMSE of the named extension (the base's
        when `"none"`), in `unit`.
    - `gain_pct`: its held-out gain, % (0 unless a cause is named).
    - `effect`: the named effect's size: `{"parameter", "value", "stderr", "unit"}`
        (empty unless a cause is named).
    - `candidates`: every [`jaxcable.Candidate`][], in the order of
        [`jaxcable.EXTENSIONS`][].
    - `structure`: the base residuals' structure: `{feature: correlation}` (the
        test conditions and every covariate with its rate and absolute rate) and
        the lag-1 autocorrelation with its white-noise band (`residual_structure`).
    - `noise`: the noise of the scored channels estimated from the data (robust,
        from second differences), in `unit`.
    - `split`: how held-out data were chosen.
    - `holdout`: the held-out fraction of every test for the time split, None for
        cross-validation by tests.
    - `test_ids`: the tests.
    - `base_fit`: the base model's [`jaxcable.FitResult`][] on the training data.
    - `unit`: the unit of every RMSE and of the noise: `"mm"` (every test driven by
        its force, its elongation scored), `"N"` (every test driven by its
        elongation, its force scored) or `"noise"` (both kinds: each residual
        divided by the noise standard deviation of its test's scored channel).
    - `drives`: each test's drive value ([`jaxcable.FORCE_DRIVEN`][] or
        [`jaxcable.ELONGATION_DRIVEN`][]; by name in the JSON).
    - `scales`: each test's residual unit (1, or in noise units the noise standard
        deviation of its scored channel, m or N).
    - `discovered`: the term [`jaxcable.discover`][] found when the catalogue did
        not explain the residual (equation, terms, covariate, coefficients with
        standard errors and units, held-out RMSEs, gain), else empty.
    - `verdict`: `"named"` (a significant candidate comes within `MAX_FLOOR_RATIO`
        x the noise held out, or explains at least `MIN_EXPLAINED_PCT` % of the
        base's excess over it), `"none"` (the base is within `MIN_EXCESS` x the
        noise: nothing to explain) or `"unexplained"` (an excess no candidate
        explains enough; the partial ones keep their `explained_pct`).
    - `base_heldout_rmse_mm`, `base_train_rmse_mm`, `extended_heldout_rmse_mm`,
        `noise_mm` (properties): the same in mm; NaN unless `unit` is mm.
    """

    base_model: str
    named_cause: str
    base_heldout_rmse: float
    base_train_rmse: float
    extended_heldout_rmse: float
    gain_pct: float
    effect: dict[str, Any]
    candidates: tuple[Candidate, ...]
    structure: dict[str, Any]
    noise: float
    split: str
    holdout: float | None
    test_ids: tuple[str, ...]
    base_fit: FitResult = dataclasses.field(repr=False, compare=False)
    unit: str = "mm"
    drives: tuple[AbstractTestDrive, ...] = ()
    scales: tuple[float, ...] = ()
    verdict: str = "none"
    discovered: dict[str, Any] = dataclasses.field(default_factory=dict)

    base_heldout_rmse_mm = _InMm("base_heldout_rmse")
    base_train_rmse_mm = _InMm("base_train_rmse")
    extended_heldout_rmse_mm = _InMm("extended_heldout_rmse")
    noise_mm = _InMm("noise")

    def extended_fit(self) -> FitResult:
        """The fit of the extended model the diagnosis names (the named candidate's
        fit on the training data), or the base's when no cause is named."""
        if self.verdict == "named" and self.named_cause not in ("none", "unexplained"):
            fit = self.candidate(self.named_cause).fit
            if fit is not None:
                return fit
        return self.base_fit

    def candidate(self, id: str) -> Candidate:
        """The candidate of this id."""
        for c in self.candidates:
            if c.id == id:
                return c
        raise ValueError(f"`id` {id!r} is not a candidate here.")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (the `--json` output of `jaxcable diagnose`): the RMSEs
        and the noise in `unit`, and, as before, in mm (None unless `unit` is mm)."""
        return {
            "named_cause": self.named_cause,
            "verdict": self.verdict,
            "base_model": self.base_model,
            "base_heldout_rmse_mm": jsonable(self.base_heldout_rmse_mm),
            "base_train_rmse_mm": jsonable(self.base_train_rmse_mm),
            "extended_heldout_rmse_mm": jsonable(self.extended_heldout_rmse_mm),
            "gain_pct": jsonable(self.gain_pct),
            "effect": {k: jsonable(v) for k, v in self.effect.items()},
            "noise_mm": jsonable(self.noise_mm),
            "unit": self.unit,
            "base_heldout_rmse": jsonable(self.base_heldout_rmse),
            "base_train_rmse": jsonable(self.base_train_rmse),
            "extended_heldout_rmse": jsonable(self.extended_heldout_rmse),
            "noise": jsonable(self.noise),
            "drives": [as_test_drive(d).name for d in self.drives],
            "split": self.split,
            "thresholds": {
                "min_gain_pct": MIN_GAIN_PCT,
                "max_delta_bic": MAX_DELTA_BIC,
                "min_size_z": MIN_SIZE_Z,
                "min_excess_over_noise": MIN_EXCESS,
                "max_heldout_over_noise": MAX_FLOOR_RATIO,
                "min_explained_pct": MIN_EXPLAINED_PCT,
                "min_autocorrelation_unexplained": MIN_AUTOCORRELATION,
            },
            "candidates": [c.to_dict() for c in self.candidates],
            "discovered": jsonable(self.discovered),
            "structure": jsonable(self.structure),
            "tests": list(self.test_ids),
        }

    def to_json(self, path=None) -> str:
        """The diagnosis as JSON text (written to `path` when given, atomically)."""
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            write_text_atomic(path, text + "\n")
        return text

    def summary(self) -> str:
        """A plain-text table: base, every candidate, the named cause."""
        u = self.unit
        w = max(12, len(u) + 10)  # the held-out column: 12 wide in mm, as ever
        lines = [
            f"jaxcable diagnose: base {self.base_model}, {len(self.test_ids)} test(s), "
            f"held out: {self.split}",
        ]
        if u != "mm":
            lines.append(_scored_line(self.drives, u))
        noise = f"{self.noise * 1e3:.3g} um" if u == "mm" else f"{self.noise:.3g} {u}"
        lines += [
            f"noise (estimated from the data) {noise}; base "
            f"RMSE {self.base_train_rmse:.4g} {u} fitted, "
            f"{self.base_heldout_rmse:.4g} {u} held out",
            "",
            f"{'candidate':<24}{'held-out ' + u:>{w}}{'gain %':>9}{'expl %':>8}"
            f"{'dBIC':>10}"
            f"{'size':>12}{'+-':>10}  unit",
        ]
        for c in self.candidates:
            if not c.applicable:
                lines.append(f"{c.id:<24}{'n/a':>{w}}  {c.note}")
                continue
            mark = " *" if c.significant else ""
            lines.append(
                f"{c.id:<24}{c.heldout_rmse:>{w}.4g}{c.gain_pct:>9.1f}"
                f"{c.explained_pct:>8.0f}"
                f"{c.delta_bic:>10.1f}{c.size:>12.4g}{c.size_stderr:>10.2g}  "
                f"{c.size_unit}{mark}"
            )
        lines.append("")
        if self.discovered:
            d = self.discovered
            covariate = f" (covariate {d['covariate']})" if d.get("covariate") else ""
            lines += [f"discovered term{covariate}: {d['equation']}", ""]
        lines += self._verdict_lines()
        return "\n".join(lines)

    def _verdict_lines(self) -> list[str]:
        """The summary's last lines: the verdict, said plainly, and the structure."""
        u = self.unit
        structure = self.structure
        strongest = structure.get("strongest")
        r_lag = structure.get("autocorrelation", math.nan)
        strong = (
            f"{strongest} (r = {structure['correlation'][strongest]:.2f})"
            if strongest
            else "none"
        )
        if self.verdict == "unexplained":
            shown = [c for c in self.candidates if math.isfinite(c.explained_pct)]
            partial = [c for c in shown if c.significant] or shown
            if partial:
                best = max(partial, key=lambda c: c.explained_pct)
                what = (
                    f"the best candidate, {best.id}, explains "
                    f"{best.explained_pct:.0f} % of the excess over the noise"
                    + ("" if best.significant else " (not significant)")
                )
            else:
                what = "no candidate could be fitted"
            lines = [
                f"verdict: unexplained — {what}; the residual stays systematic "
                f"(lag-1 autocorrelation {r_lag:.2f}); strongest structure: {strong}",
            ]
            others = [c for c in partial if c is not best and c.significant]
            if others:
                lines.append(
                    "other partial candidates: "
                    + ", ".join(f"{c.id} {c.explained_pct:.0f} %" for c in others)
                )
            lines.append(
                f"(a cause is named when it comes within {MAX_FLOOR_RATIO:g} x the "
                f"noise held out or explains >= {MIN_EXPLAINED_PCT:g} % of the "
                "excess)"
            )
            return lines
        if self.named_cause == "none" and (
            not self.base_heldout_rmse > MIN_EXCESS * self.noise
        ):
            against = (
                f"{self.base_heldout_rmse * 1e3:.3g} um against "
                f"{self.noise * 1e3:.3g} um"
                if u == "mm"
                else f"{self.base_heldout_rmse:.3g} {u} against {self.noise:.3g} {u}"
            )
            lines = [
                f"verdict: none — the base predicts the held-out data to within "
                f"{MIN_EXCESS:g} x the noise ({against}): nothing to explain"
            ]
        elif self.named_cause == "none":
            lines = [
                "verdict: none — no candidate improves the held-out RMSE "
                f"significantly: gain >= {MIN_GAIN_PCT:g} %, dBIC <= "
                f"{MAX_DELTA_BIC:g}, size >= {MIN_SIZE_Z:g} standard errors; and "
                f"the residual left is not systematic (lag-1 autocorrelation "
                f"{r_lag:.2f} < {MIN_AUTOCORRELATION:g})"
            ]
        else:
            e = self.effect
            named = self.candidate(self.named_cause)
            lines = [
                f"named cause: {self.named_cause}: {e['parameter']} = "
                f"{e['value']:.4g} +- {e['stderr']:.2g} {e['unit']}; held-out RMSE "
                f"{self.base_heldout_rmse:.4g} -> "
                f"{self.extended_heldout_rmse:.4g} {u} ({self.gain_pct:.1f} % gain)",
                f"verdict: named — it explains {named.explained_pct:.0f} % of the "
                "excess over the noise; held-out RMSE "
                f"{self.extended_heldout_rmse / self.noise:.2f} x the noise",
            ]
        if strongest:
            lines.append(
                f"base residuals relate most to: {strong}; lag-1 "
                f"autocorrelation {r_lag:.2f} (white "
                f"noise: |r| < {structure['white_noise_band']:.2g})"
            )
        return lines


def _scored_line(drives: tuple, unit: str) -> str:
    """What a diagnosis not in mm scores: one line for the summary."""
    if unit == "N":
        return "scored: the force, N (every test driven by its elongation)"
    by_force = sum(not as_test_drive(d).scores_force for d in drives)
    return (
        f"scored: {by_force} force-driven test(s) by their elongation, "
        f"{len(drives) - by_force} elongation-driven by their force; residuals in "
        "noise units (each divided by the noise of its test's scored channel)"
    )
