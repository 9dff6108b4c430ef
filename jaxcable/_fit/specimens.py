"""The specimens of `jaxcable.fit_each`: their padded tests grouped by structure and
stacked on the host, each group's least-squares problem, and the result of a
specimen that failed."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .._drive import Simulation, Trajectory
from .._models import AbstractCableModel
from .._results import RESULTS
from .data import PaddedTests, test_id
from .problem import ResidualProblem, _start, build_problem
from .result import FitResult, concrete_result
from .statistics import Statistics


# How `pad_tests` pads each field: None repeats the last sample, else this value (a
# padding sample neither drives the model nor enters the residual).
_FILL = {
    "time": None,
    "force": None,
    "elongation": 0.0,
    "simulate": False,
    "weight": 0.0,
    "temperature": None,
    "covariate": None,
}


@dataclasses.dataclass(frozen=True)
class Group:
    """Specimens whose padded tests have one structure (number of tests, drives),
    stacked for one vmapped kernel.

    **Fields:**

    - `indices`: the specimens' positions in `fit_each`'s `specimens`.
    - `tests`: each specimen's list of tests.
    - `host`: the stacked `PaddedTests` (NumPy leaves, shape `(specimens, tests,
        samples)`), every specimen padded to the group's longest.
    - `data`: `host` on the device.
    """

    indices: tuple[int, ...]
    tests: tuple[list, ...]
    host: PaddedTests
    data: PaddedTests

    @property
    def num_tests(self) -> int:
        return int(self.host.time.shape[1])


def _padded(x: np.ndarray, length: int, fill) -> np.ndarray:
    """`x` (tests, samples) padded to `length` samples as `pad_tests` pads it."""
    extra = length - x.shape[1]
    if not extra:
        return x
    if fill is None:
        tail = np.repeat(x[:, -1:], extra, axis=1)
    else:
        tail = np.full((x.shape[0], extra), fill, x.dtype)
    return np.concatenate([x, tail], axis=1)


def _stacked(datas: list[PaddedTests]) -> PaddedTests:
    """The specimens' `PaddedTests` (one structure) padded to one length and
    stacked on a leading axis, on the host."""
    host = [jax.device_get(d) for d in datas]
    length = max(d.time.shape[1] for d in host)
    fields = {
        name: np.stack([_padded(getattr(d, name), length, fill) for d in host])
        for name, fill in _FILL.items()
    }
    # NumPy leaves where PaddedTests declares jax arrays: they stay on the host until
    # the kernel's call transfers them.
    return PaddedTests(
        **fields,  # pyright: ignore[reportArgumentType]
        cable=jax.tree.map(lambda *xs: np.stack(xs), *(d.cable for d in host)),
        drive=host[0].drive,
        scale=np.stack([d.scale for d in host]),  # pyright: ignore[reportArgumentType]
    )


def grouped(specimens: list[list], datas: list[PaddedTests]) -> list[Group]:
    """The specimens grouped by the structure of their padded tests (the number of
    tests and their drives), in order of first appearance."""
    by_structure: dict = {}
    for k, data in enumerate(datas):
        by_structure.setdefault(jax.tree.structure(data), []).append(k)
    groups = []
    for indices in by_structure.values():
        host = _stacked([datas[k] for k in indices])
        groups.append(
            Group(
                indices=tuple(indices),
                tests=tuple(specimens[k] for k in indices),
                host=host,
                data=jax.device_put(host),
            )
        )
    return groups


def lane(tree, j: int):
    """Entry `j` of the leading axis of every leaf of `tree`."""
    return jax.tree.map(lambda x: x[j], tree)


def group_problem(
    model: AbstractCableModel, template: ResidualProblem, group: Group
) -> tuple[ResidualProblem, jax.Array]:
    """The problem of `group`'s specimens (its data: the first specimen's) and the
    start u: `template`'s (from `make_problem` of any specimen) for the group's
    number of tests."""
    layout = dataclasses.replace(template.layout, num_tests=group.num_tests)
    scales, start = _start(model, layout)
    problem = build_problem(
        layout, template.base, template.static, scales, lane(group.host, 0)
    )
    return problem, jnp.asarray(start, jnp.result_type(float))


def failing_start(model, tests: list, drives, ok: np.ndarray) -> tuple[int, Trajectory]:
    """The first test on which the start does not simulate (`ok` False for some),
    and its simulation re-run without raising, for the reason: `(index,
    trajectory)`."""
    i = int(np.flatnonzero(~ok)[0])
    test, drive = tests[i], drives[i]
    traj = drive.simulate(
        model,
        test.cable(),
        test.time,
        drive.imposed_of(test),
        method=Simulation(throw=False),
    )
    return i, traj


def start_failure(model, tests: list, drives, ok: np.ndarray) -> RESULTS:
    """Why the start does not simulate on a specimen's tests (`ok` False for some):
    the simulation's result on the first such test, re-run as `jaxcable.fit` does
    for its error."""
    _, traj = failing_start(model, tests, drives, ok)
    result = concrete_result(jax.device_get(traj.result))
    # The residuals were not finite although the simulation succeeded: a start
    # the solver cannot use, as when every start fails.
    return RESULTS.every_start_failed if result is RESULTS.successful else result


def failed_result(
    model: AbstractCableModel,
    problem: ResidualProblem,
    tests: list,
    per_test: tuple[str, ...],
    num_starts: int,
    result: RESULTS,
) -> FitResult:
    """The [`jaxcable.FitResult`][] of a specimen that was not fitted: the start
    model, NaN statistics and errors, and `result`."""
    layout, data = problem.layout, problem.data
    stats = Statistics.undefined(layout.size)
    nan = np.full(layout.num_tests, np.nan)
    return FitResult(
        model=model,
        models=(model,) * layout.num_tests,
        names=layout.labels,
        units=tuple(u for u, s in zip(layout.units, layout.sizes) for _ in range(s)),
        values=stats.values,
        stderr=stats.stderr,
        covariance=stats.covariance,
        correlation=stats.correlation,
        singular_values=stats.singular_values,
        loss=float("nan"),
        rmse_mm=nan,
        rmse_percent=nan,
        rmse_N=nan,
        drives=data.drive,
        loss_unit={"m": "m^2", "N": "N^2", "1": "1"}[data.units[0]],
        test_ids=tuple(test_id(t, i) for i, t in enumerate(tests)),
        num_samples=np.asarray(data.weight).sum(axis=1).astype(int),
        warnings=(),
        result=result,
        num_steps=0,
        start_losses=np.full(num_starts, np.inf),
        per_test=per_test,
    )
