"""The result of a diagnosis: the scored candidate extensions (`Candidate`), the
decision (`Diagnosis`) with its JSON and plain-text forms, and the thresholds that
decide significance."""

import dataclasses
import json
import math
from typing import Any

import numpy as np

from .._files import write_text_atomic
from .._fit import FitResult


# Significance thresholds of a candidate (see `jaxcable.diagnose`).
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
        """A JSON-ready dict of the scores (the fit left out; NaN as None)."""
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
        """The diagnosis as JSON text (written to `path` when given, atomically)."""
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            write_text_atomic(path, text + "\n")
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
    """`x` with NumPy scalars as Python numbers and non-finite floats as None (JSON
    has no NaN), through dicts, lists and tuples."""
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
