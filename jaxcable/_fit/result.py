"""The outcome of a fit, `FitResult`: its text summary and its PARAMS.json form."""

import dataclasses
import importlib.metadata
import json
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._drive import FORCE_DRIVEN, AbstractTestDrive, as_test_drive
from .._files import write_text_atomic
from .._io import parse_json, read_json
from .._json import from_json_number, jsonable
from .._models import AbstractCableModel
from .._results import RESULTS
from .parameters import test_slice
from .serialize import model_document, model_from_document, unknown_model


def _result_name(result: RESULTS) -> str:
    """The name of a [`jaxcable.RESULTS`][] member, as PARAMS.json writes it."""
    index = int(np.asarray(result._value))
    # equinox's enumerations keep their members by name.
    names = RESULTS._name_to_item.items()
    return next(name for name, item in names if int(item._value) == index)


def concrete_result(result: RESULTS) -> RESULTS:
    """The member itself of a concrete result (whose value may be a device array)."""
    return RESULTS._name_to_item[_result_name(result)]


def _read_result(doc: Mapping[str, Any]) -> RESULTS:
    """The fit's result in a PARAMS.json: its `result` name; in a file written before
    results, the member whose message is the file's `message`."""
    if "result" in doc:
        return RESULTS._name_to_item[doc["result"]]
    if doc["converged"]:
        return RESULTS.successful
    message = doc.get("message", "")
    if message.startswith("every start failed"):
        return RESULTS.every_start_failed
    by_message = {str(RESULTS[item]): item for item in RESULTS._name_to_item.values()}
    return by_message[message]


def _json_matrix(matrix: np.ndarray) -> list[list]:
    return [[jsonable(float(c)) for c in row] for row in matrix]


@dataclasses.dataclass(frozen=True, eq=False)
class FitResult:
    """The outcome of [`jaxcable.fit`][]: fitted model(s), errors and uncertainty.

    **Fields:**

    - `model`: the fitted model. Shared parameters hold their fitted value; a
        per-test parameter holds a `(tests,)` array (a batch for `jax.vmap`).
    - `models`: one model per test, each with its own per-test values.
    - `names`: labels of the fitted parameters; a per-test parameter `p` appears as
        `p[0]`, `p[1]`, ... (test order).
    - `units`: unit of each fitted parameter (SI; `-` dimensionless).
    - `values`: fitted values, SI.
    - `stderr`: standard errors, SI: sqrt of the diagonal of `covariance` (inf for
        a parameter the residuals do not depend on; huge, not inf, for one in a
        direction the data do not determine, whose eigenvalue of J^T J is raised to
        1e-13 of the largest).
    - `covariance`: sigma^2 (J^T J)^-1 in the unconstrained parameters u, with
        sigma^2 = SSR / (n - p) (n fitted samples, p parameters) and J the Jacobian
        of the residuals (m) at the optimum, carried to the natural parameters by the
        delta method, G C G^T with G = dx/du.
    - `correlation`: `covariance` normalised by `stderr`.
    - `singular_values`: of J (in u), largest first.
    - `loss`: sum of squared residuals at the optimum, SSR, in `loss_unit`.
    - `rmse_mm`: RMS elongation residual of each force-driven test over its fitted
        samples, mm (NaN for an elongation-driven test).
    - `rmse_percent`: each test's RMS residual as a percentage of its largest
        |measured value| in its scored channel (Park et al. report errors as RMSE
        in mm and as this percentage of the peak elongation).
    - `test_ids`: each test's `metadata['id']`, file name or `test i`.
    - `num_samples`: fitted (unmasked) samples per test.
    - `warnings`: the identifiability warnings (also issued with `warnings.warn`).
    - `result`: a [`jaxcable.RESULTS`][]: `successful` when the chosen start's
        solver run converged, else the solver's result (optimistix's members, e.g.
        `max_steps_reached`) or `every_start_failed`.
    - `num_steps`: solver steps of the chosen start.
    - `start_losses`: SSR reached from each start (m^2; inf where it failed).
    - `per_test`: the names fitted per test.
    - `rmse_N`: RMS force residual of each elongation-driven test, N (NaN for a
        force-driven test); `None` in results read from files written before drives.
    - `drives`: each test's drive, [`jaxcable.FORCE_DRIVEN`][] or
        [`jaxcable.ELONGATION_DRIVEN`][] (see [`jaxcable.fit`][]); PARAMS.json
        writes their names.
    - `loss_unit`: `"m^2"` (every test force-driven), `"N^2"` (every test
        elongation-driven) or `"1"` (both: residuals in noise units).
    - `start_note`: "" when the fit started from the given start; else why that
        start failed on a test and how it was moved (scaled to the data,
        [`jaxcable.scaled_start`][]).
    """

    model: AbstractCableModel
    models: tuple[AbstractCableModel, ...]
    names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    singular_values: np.ndarray
    loss: float
    rmse_mm: np.ndarray
    rmse_percent: np.ndarray
    test_ids: tuple[str, ...]
    num_samples: np.ndarray
    warnings: tuple[str, ...]
    result: RESULTS
    num_steps: int
    start_losses: np.ndarray
    per_test: tuple[str, ...] = ()
    rmse_N: np.ndarray | None = None
    drives: tuple[AbstractTestDrive, ...] = ()
    loss_unit: str = "m^2"
    start_note: str = ""

    @property
    def converged(self) -> bool:
        """Whether the chosen start's solver run converged (`result` is
        `RESULTS.successful`)."""
        return _result_name(self.result) == "successful"

    @property
    def message(self) -> str:
        """The message of `result` ("" when the fit converged)."""
        return str(RESULTS[self.result])

    @property
    def params(self) -> dict[str, float]:
        """{label: fitted value, SI}."""
        return {n: float(v) for n, v in zip(self.names, self.values)}

    @property
    def relative_error(self) -> np.ndarray:
        """stderr / |value| of each fitted parameter (inf for a zero value)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.values != 0, self.stderr / np.abs(self.values), np.inf)

    def drive(self, i: int) -> AbstractTestDrive:
        """Test i's drive (force-driven for a result without `drives`)."""
        return self.drives[i] if self.drives else FORCE_DRIVEN

    def rmse(self, i: int) -> tuple[float, str]:
        """Test i's RMS residual in its scored channel and that channel's unit
        (`"mm"` or `"N"`)."""
        drive = self.drive(i)
        if drive.scores_force:
            assert self.rmse_N is not None  # set when a test is elongation-driven
            value = self.rmse_N[i]
        else:
            value = self.rmse_mm[i]
        return float(value), drive.report_unit

    def outcome_text(self, failed: str = "NOT converged") -> str:
        """The solver's outcome in words, as the reports print it: `converged in N
        steps`, else `failed` followed by the solver's message in parentheses."""
        if self.converged:
            return f"converged in {self.num_steps} steps"
        return f"{failed} ({self.message})"

    def _per_test_rows(self):
        return zip(self.test_ids, self.num_samples, self.rmse_mm, self.rmse_percent)

    def summary(self) -> str:
        """A text report: the fit, the per-test errors, the parameter table with
        standard errors, the correlation matrix and the warnings.

        **Returns:**

        The report as a multi-line string.
        """
        n = int(np.sum(self.num_samples))
        lines = [
            f"jaxcable fit: {type(self.model).__name__}, {len(self.test_ids)} test(s), "
            f"{n} samples, {len(self.names)} parameters",
            f"SSR {self.loss:.6g} {self.loss_unit}; {self.outcome_text()}; "
            f"best of {len(self.start_losses)} start(s)",
            "",
        ]
        # equinox Modules hash (frozen); pyright takes them for unhashable.
        if set(self.drives) <= {FORCE_DRIVEN}:  # pyright: ignore[reportUnhashable]
            lines.append(f"{'test':<24} {'samples':>8} {'RMSE mm':>10} {'RMSE %':>8}")
            for tid, k, mm, pct in self._per_test_rows():
                lines.append(f"{tid[:24]:<24} {int(k):>8} {mm:>10.4f} {pct:>8.2f}")
        else:
            lines.append(
                f"{'test':<24} {'drive':>10} {'samples':>8} {'RMSE':>10}      "
                f"{'RMSE %':>8}"
            )
            for i, (tid, k, pct) in enumerate(
                zip(self.test_ids, self.num_samples, self.rmse_percent)
            ):
                value, unit = self.rmse(i)
                lines.append(
                    f"{tid[:24]:<24} {self.drive(i).name:>10} {int(k):>8} "
                    f"{value:>10.4g} {unit:<4} {pct:>8.2f}"
                )
        lines += [
            "",
            f"{'parameter':<12} {'value':>12} {'std err':>10} {'rel %':>8}  unit",
        ]
        for name, v, s, r, u in zip(
            self.names, self.values, self.stderr, self.relative_error, self.units
        ):
            lines.append(f"{name:<12} {v:>12.5g} {s:>10.3g} {100 * r:>8.3g}  {u}")
        if len(self.names) > 1:
            lines += ["", "correlation:"]
            width = max(7, max(len(x) for x in self.names) + 1)
            lines.append(" " * width + "".join(f"{x[:7]:>8}" for x in self.names))
            for name, row in zip(self.names, self.correlation):
                lines.append(f"{name:<{width}}" + "".join(f"{c:>8.3f}" for c in row))
        if self.warnings:
            lines += ["", "warnings:"] + [f"  - {w}" for w in self.warnings]
        if self.start_note:
            lines += ["", f"start moved: {self.start_note}"]
        return "\n".join(lines)

    def to_json(self, path: str | os.PathLike | None = None) -> str:
        """The fit as PARAMS.json: every model parameter by name (SI) plus metadata.

        `parameters` holds every array field of the model (fitted and fixed), a list
        per test for per-test parameters; `static` the model's non-array settings;
        `fitted`, `stderr` and `correlation` the fitted parameters' statistics; `tests`
        each test's id, samples and RMSE. Non-finite numbers are written as null.

        **Arguments:**

        - `path`: optional file to write (atomically: a write cut short leaves the
            old file).

        **Returns:**

        The JSON text.
        """
        fitted = zip(self.names, self.values, self.stderr, self.units)
        document = {
            "format": "jaxcable-params",
            "format_version": 1,
            "jaxcable_version": importlib.metadata.version("jaxcable"),
            **model_document(self.model),
            "units": "SI (N, m, s, Pa, Pa s)",
            "per_test": list(self.per_test),
            "fitted": [
                {
                    "name": n,
                    "value": float(v),
                    "stderr": jsonable(float(s)),
                    "unit": u,
                }
                for n, v, s, u in fitted
            ],
            "correlation": _json_matrix(self.correlation),
            "covariance": _json_matrix(self.covariance),
            "singular_values": [jsonable(float(s)) for s in self.singular_values],
            "tests": [
                {
                    "id": tid,
                    "samples": int(k),
                    "drive": self.drive(i).name,
                    "rmse_mm": jsonable(float(mm)),
                    "rmse_N": jsonable(self.rmse(i)[0])
                    if self.drive(i).scores_force
                    else None,
                    "rmse_percent": jsonable(float(pct)),
                }
                for i, (tid, k, mm, pct) in enumerate(self._per_test_rows())
            ],
            "loss_m2": float(self.loss),
            "loss_unit": self.loss_unit,
            "result": _result_name(self.result),
            "converged": bool(self.converged),
            "message": self.message,
            "num_steps": int(self.num_steps),
            "start_losses": [jsonable(float(x)) for x in self.start_losses],
            "warnings": list(self.warnings),
            "start_note": self.start_note,
        }
        text = json.dumps(document, indent=2)
        if path is not None:
            write_text_atomic(path, text + "\n")
        return text

    @classmethod
    def from_json(cls, source: str | os.PathLike) -> "FitResult":
        """Read a PARAMS.json written by [`jaxcable.FitResult.to_json`][].

        **Arguments:**

        - `source`: a path, or the JSON text itself (a string starting with `{`).

        **Returns:**

        A [`jaxcable.FitResult`][]; `result.model` is the fitted model, ready to
        simulate.

        **Raises:**

        `ValueError` naming `source` for text that is not such a file, or a model
        class jaxcable does not know.
        """
        is_text = isinstance(source, str) and source.lstrip().startswith("{")
        where = "<json text>" if is_text else str(source)
        try:
            if is_text:
                doc = parse_json(str(source), where)
            else:
                doc = read_json(source, "a PARAMS.json")
        except ValueError as e:
            # The reader's message names the file (and the line and column).
            raise ValueError(f"`source` {e}") from None
        if not isinstance(doc, dict) or doc.get("format") != "jaxcable-params":
            raise ValueError(
                f"`source` {where}: not a jaxcable PARAMS.json (no "
                "'format': 'jaxcable-params')."
            )
        unknown = unknown_model(doc)
        if unknown is not None:
            raise ValueError(f"`source` {where}: {unknown}")
        try:
            return cls._from_document(doc)
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as e:
            raise ValueError(
                f"`source` {where}: malformed PARAMS.json ({e})."
            ) from None

    @classmethod
    def _from_document(cls, doc: Mapping[str, Any]) -> "FitResult":
        """The result of a decoded PARAMS.json whose models are known; a missing or
        malformed entry raises `KeyError`, `TypeError` or `ValueError`."""
        model = model_from_document(doc)
        fitted = doc["fitted"]
        tests = doc["tests"]

        def matrix(key):
            return np.array(
                [[from_json_number(c) for c in row] for row in doc[key]],
                dtype=float,
            ).reshape(len(fitted), len(fitted))

        return cls(
            model=model,
            models=tuple(test_slice(model, i) for i in range(len(tests))),
            names=tuple(p["name"] for p in fitted),
            units=tuple(p.get("unit", "") for p in fitted),
            values=np.array([p["value"] for p in fitted], float),
            stderr=np.array([from_json_number(p["stderr"]) for p in fitted]),
            covariance=matrix("covariance"),
            correlation=matrix("correlation"),
            singular_values=np.array(
                [from_json_number(s) for s in doc.get("singular_values", [])]
            ),
            loss=float(doc["loss_m2"]),
            rmse_mm=np.array([from_json_number(t["rmse_mm"]) for t in tests]),
            rmse_percent=np.array([from_json_number(t["rmse_percent"]) for t in tests]),
            rmse_N=np.array([from_json_number(t.get("rmse_N")) for t in tests]),
            drives=tuple(as_test_drive(t.get("drive", "force")) for t in tests),
            loss_unit=doc.get("loss_unit", "m^2"),
            test_ids=tuple(t["id"] for t in tests),
            num_samples=np.array([t["samples"] for t in tests], int),
            warnings=tuple(doc.get("warnings", [])),
            result=_read_result(doc),
            num_steps=int(doc["num_steps"]),
            start_losses=np.array(
                [from_json_number(x) for x in doc.get("start_losses", [])]
            ),
            per_test=tuple(doc.get("per_test", [])),
            start_note=doc.get("start_note", ""),
        )
