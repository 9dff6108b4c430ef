"""What a diagnosis gives: the scored candidate extensions (`Candidate`) and the
decision (`Diagnosis`) with its JSON and plain-text forms."""

import dataclasses
import json
import math
from typing import TYPE_CHECKING, Any

from .._drive import AbstractTestDrive, as_test_drive
from .._files import write_text_atomic
from .._fit import FitResult
from .._json import jsonable
from .rule import thresholds
from .summary import summary


if TYPE_CHECKING:
    from .family import FamilyCheck


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


def shift_reference(model) -> dict[str, Any]:
    """The reference of the outermost time shift `model` is (its `T_ref`, K, or
    `c_ref`): `{"field", "value", "unit"}` (and `"celsius"` for a temperature);
    empty when `model` is no shift."""
    for field, unit in (("T_ref", "K"), ("c_ref", "[c]")):
        value = getattr(model, field, None)
        if value is not None and hasattr(model, "log_shift_at"):
            out = {"field": field, "value": float(value), "unit": unit}
            if field == "T_ref":
                out["celsius"] = float(value) - 273.15
            return out
    return {}


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
    - `explained_rmse_pct`: the same share on the RMSEs themselves, %: 100 (base -
        candidate) / (base - floor); the residual left is what the summary shows
        beside it.
    - `covariate`: the extra column the candidate reads, or None.
    - `diverging`: "" or why the candidate is not ranked: its held-out RMSE is more
        than `MAX_DIVERGENCE` x the base's (which test, from when it departs).
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
    explained_rmse_pct: float = math.nan
    covariate: str | None = None
    diverging: str = ""

    heldout_rmse_mm = _InMm("heldout_rmse")
    train_rmse_mm = _InMm("train_rmse")

    @property
    def reference(self) -> dict[str, Any]:
        """The reference of a time shift's fit (a = 1 there: its base is the
        material at it): `{"field", "value", "unit"}` (`T_ref` in K with `"celsius"`
        beside it; a covariate shift's `c_ref` in its column's unit); empty for
        any other candidate."""
        return shift_reference(None if self.fit is None else self.fit.model)

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
        out["reference"] = self.reference
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
    - `noise`: the noise of the scored channels estimated from the data, in `unit`:
        robust, from second differences, unless the record is smooth (filtered,
        interpolated, digitised, processed), where a floor replaces them: the
        record's quantisation step / sqrt(12) or the white part of the base
        residual (the rule: `jaxcable._diagnose.noise`, docs/diagnosis.md).
    - `noise_source`: which estimate `noise` is and why, in words ("second
        differences", "quantisation step 0.01 mm (step / sqrt(12))", "white part of
        the base residual (record smooth: second differences 40x below)").
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
    - `causes`: every cause named, in the order found (round 1's is
        `named_cause`): after a cause is named the diagnosis looks again with the
        extended model as its base, until what is left is within
        `MAX_FLOOR_RATIO` x the noise, nothing more is significant, or the rounds
        run out. Empty when the verdict is `"none"` or `"unexplained"`.
    - `cause_gains`: each cause's held-out gain over its round's base, %.
    - `final_heldout_rmse`: the held-out RMSE of the model with every cause of
        `causes` (the base's when there is none), in `unit`.
    - `rounds`: each round's own `Diagnosis` (its base, candidates and decision;
        the first is this one's), including a round whose cause was tried and not
        kept (`accepted` False).
    - `accepted`: for a round: whether what it named belongs to `causes` (a
        partial cause is kept only when the causes after it, together, explain
        the excess; an early cause is dropped when the later ones make it
        redundant: see [`jaxcable.diagnose`][]).
    - `note`: for a round whose cause was not kept: why.
    - `covariate`: the extra column the base reads (a covariate's extension named
        in an earlier round), or None.
    - `family`: which family of base models the data want, checked in the first
        round before any candidate when the base is far from the data
        (`jaxcable._diagnose.family.FamilyCheck`: each family's held-out RMSE and
        BIC, the family the rounds ran on and why), or None (a round after the
        first).
    - `base_heldout_rmse_mm`, `base_train_rmse_mm`, `extended_heldout_rmse_mm`,
        `final_heldout_rmse_mm`, `noise_mm` (properties): the same in mm; NaN
        unless `unit` is mm.
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
    causes: tuple[str, ...] = ()
    cause_gains: tuple[float, ...] = ()
    final_heldout_rmse: float = math.nan
    rounds: tuple["Diagnosis", ...] = dataclasses.field(default=(), repr=False)
    accepted: bool = True
    note: str = ""
    covariate: str | None = None
    final_fit: FitResult | None = dataclasses.field(
        default=None, repr=False, compare=False
    )
    family: "FamilyCheck | None" = dataclasses.field(default=None, compare=False)
    noise_source: str = ""

    def __post_init__(self):
        # The estimate carries its source (a `jaxcable._diagnose.noise.Noise`):
        # every round's diagnosis says where its noise came from.
        if not self.noise_source:
            source = getattr(self.noise, "source", "second differences")
            object.__setattr__(self, "noise_source", source)

    base_heldout_rmse_mm = _InMm("base_heldout_rmse")
    final_heldout_rmse_mm = _InMm("final_heldout_rmse")
    base_train_rmse_mm = _InMm("base_train_rmse")
    extended_heldout_rmse_mm = _InMm("extended_heldout_rmse")
    noise_mm = _InMm("noise")

    def extended_fit(self) -> FitResult:
        """The fit of the extended model the diagnosis names, with every cause of
        `causes` (the last round's named candidate's fit on the training data), or
        the base's when no cause is named."""
        if self.final_fit is not None:
            return self.final_fit
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
            "noise_source": self.noise_source,
            "drives": [as_test_drive(d).name for d in self.drives],
            "split": self.split,
            "thresholds": thresholds(),
            "causes": list(self.causes),
            "cause_gains_pct": [jsonable(g) for g in self.cause_gains],
            "final_heldout_rmse": jsonable(self.final_heldout_rmse),
            "final_heldout_rmse_mm": jsonable(self.final_heldout_rmse_mm),
            "rounds": [r.round_dict() for r in self.rounds],
            "candidates": [c.to_dict() for c in self.candidates],
            "discovered": jsonable(self.discovered),
            "structure": jsonable(self.structure),
            "tests": list(self.test_ids),
            "family": None if self.family is None else self.family.to_dict(),
        }

    def round_dict(self) -> dict[str, Any]:
        """One round for the JSON: its base, decision and candidates."""
        return {
            "base_model": self.base_model,
            "base_heldout_rmse": jsonable(self.base_heldout_rmse),
            "named_cause": self.named_cause,
            "verdict": self.verdict,
            "accepted": self.accepted,
            "note": self.note,
            "covariate": self.covariate,
            "extended_heldout_rmse": jsonable(self.extended_heldout_rmse),
            "gain_pct": jsonable(self.gain_pct),
            "effect": {k: jsonable(v) for k, v in self.effect.items()},
            "noise": jsonable(self.noise),
            "noise_source": self.noise_source,
            "discovered": jsonable(self.discovered),
            "candidates": [c.to_dict() for c in self.candidates],
        }

    def to_json(self, path=None) -> str:
        """The diagnosis as JSON text (written to `path` when given, atomically)."""
        text = json.dumps(self.to_dict(), indent=2)
        if path is not None:
            write_text_atomic(path, text + "\n")
        return text

    def summary(self) -> str:
        """A plain-text table per round: base, every candidate, what was named, and
        what is left."""
        return summary(self)
