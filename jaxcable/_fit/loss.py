"""The fit's loss as a pure function, for your own optimiser:
`jaxcable.make_loss`."""

from collections.abc import Callable

import equinox as eqx
from jaxtyping import Array, Float

from .._models import AbstractCableModel
from .._problem import Problem
from .problem import make_problem


def make_loss(
    problem: Problem,
) -> tuple[
    Callable[[dict[str, Array]], Float[Array, ""]],
    dict[str, Array],
    Callable[[dict[str, Array]], AbstractCableModel],
]:
    """The fit's loss as a pure function of unconstrained parameters, for your own
    optimiser (optax, ...).

    The same problem as [`jaxcable.fit`][] solves: the sum of squared residuals
    (model minus measured elongation, m^2, or force, N^2, by each test's drive;
    masked samples excluded) over all tests,
    as a function of a dict of unconstrained parameters (log of the positive ones;
    see [`jaxcable.fit`][] for each model's reparameterisation).

    ```python
    problem = jc.Problem(jc.BurgersModel(), tests)
    loss, params, to_model = jc.make_loss(problem)  # log-parameters
    opt = optax.adam(1e-2); state = opt.init(params)
    step = jax.jit(lambda p, s: opt.update(jax.grad(loss)(p), s))
    for _ in range(2000):
        updates, state = step(params, state); params = optax.apply_updates(params, updates)
    fitted = to_model(params)
    ```

    ([`jaxcable.fit`][]'s Levenberg-Marquardt on the same problem typically needs
    10-20 steps, and reports standard errors.)

    **Arguments:**

    - `problem`: a [`jaxcable.Problem`][]: its model gives the start.

    **Returns:**

    `(loss, params, to_model)`: `loss(params)`, the sum of squared residuals, m^2
    (jittable, differentiable; NaN where a simulation fails); `params`, the start, a
    dict {name: unconstrained value}, a scalar for shared and a `(tests,)` array for
    per-test parameters; `to_model(params)`, the model with those values (per-test
    fields as `(tests,)` arrays).

    **Raises:**

    `TypeError` naming `problem` when it is not a `Problem`; `ValueError` naming the
    field, as [`jaxcable.fit`][].
    """
    if not isinstance(problem, Problem):
        raise TypeError(
            f"`problem` must be a jaxcable.Problem, got {type(problem).__name__}."
        )
    residual_problem, u0 = make_problem(
        problem.model,
        list(problem.tests),
        problem.fit,
        problem.per_test,
        problem.transform_map,
        problem.drive,
        problem.covariate,
    )
    layout = residual_problem.layout

    def loss(params: dict[str, Array]) -> Float[Array, ""]:
        return residual_problem.ssr(layout.join(params))

    def to_model(params: dict[str, Array]) -> AbstractCableModel:
        return eqx.combine(
            residual_problem.params(layout.join(params)), residual_problem.static
        )

    return loss, layout.split(u0), to_model
