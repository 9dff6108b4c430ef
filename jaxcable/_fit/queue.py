"""The fits of many specimens as a queue of solves on a fixed number of lanes: the
kernel of `jaxcable.fit_each`.

Every specimen's fit is `fit_kernel`'s: its data-derived start and perturbed starts,
one least-squares solve from each, the best of them. Vmapping `fit_kernel` over the
specimens would run every solve in lockstep, until the slowest of all of them has
stopped: a batch of solves that take 20 steps, with one that runs to 256, would pay
256 steps for each. Here the solves (specimen x start) wait in a queue, and a vmapped
loop runs a fixed number of them at once, one step at a time; a lane whose solve has
stopped stores it and takes the next solve waiting. Each solve's iterates are its
own (`lanes`), so the results are `fit_kernel`'s, specimen by specimen.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, Float, Int, PRNGKeyArray

from .data import PaddedTests
from .lanes import Lane, finish_at, lane_advance, lane_init
from .problem import ResidualProblem
from .solver import KernelMethod, KernelOut, kernel_choose, kernel_starts


# The lanes of the queue. Fewer lanes than solves make a lane that finishes early take
# another solve instead of idling. On a CPU a lane's step costs about the same at any
# width, so few lanes waste least: 256 specimens x 4 starts (benchmarks/
# fit_each_small.py) took 4.3-4.5 s warm on 4 to 32 lanes, 6.6 s on 128 and 19 s on
# all 1024. An accelerator's step is wide: an eighth of the solves, at least 64.
CPU_LANES = 16
LANE_FRACTION = 8
MIN_LANES = 64


def num_lanes(jobs: int) -> int:
    """The lanes that run `jobs` solves on JAX's default backend."""
    if jax.default_backend() == "cpu":
        return min(jobs, CPU_LANES)
    return min(jobs, max(MIN_LANES, math.ceil(jobs / LANE_FRACTION)))


class _Queue(eqx.Module):
    """The queue's loop carry: the solve of each lane (`job`, -1 for none), the
    lanes, the stored end of each solve, and the next solve waiting."""

    job: Int[Array, " lanes"]
    lanes: Lane
    store: Lane
    next: Int[Array, ""]


def _kept(lane: Lane) -> Lane:
    # What the store keeps of a stopped solve: not its solver state, whose residuals
    # and Jacobian (most of its size) `finish_at` evaluates again.
    return Lane(lane.y, lane.num_steps, None, lane.terminate, lane.result)


def _at(problem: ResidualProblem, data: PaddedTests, specimen) -> ResidualProblem:
    return eqx.tree_at(
        lambda p: p.data, problem, jtu.tree_map(lambda x: x[specimen], data)
    )


def _select(mask, new, old):
    return jtu.tree_map(
        lambda a, b: jnp.where(
            jnp.reshape(mask, mask.shape + (1,) * (a.ndim - 1)), a, b
        ),
        new,
        old,
    )


@eqx.filter_jit
def each_kernel(
    problem: ResidualProblem,
    data: PaddedTests,
    u_user: Float[Array, " p"],
    key: PRNGKeyArray,
    method: KernelMethod,
) -> KernelOut:
    """`fit_kernel` of every specimen: `problem` with its data replaced by each
    specimen's (`data`, stacked on a leading axis); the other arguments as in
    `fit_kernel`, the same for every specimen.

    **Returns:**

    The `KernelOut` of every specimen, stacked on a leading axis.
    """
    solver, jac, max_steps = method.solver, method.jac, method.max_steps
    specimens = jax.tree_util.tree_leaves(data)[0].shape[0]
    starts, start_ok = jax.vmap(
        lambda d: kernel_starts(_at(problem, data, d), u_user, key, method)
    )(jnp.arange(specimens))
    n = method.num_starts
    jobs = specimens * n
    u0 = jnp.reshape(starts, (jobs, -1))

    def init(job):
        # A lane with no solve (-1) holds the first one, stopped.
        lane = lane_init(
            _at(problem, data, jnp.maximum(job, 0) // n),
            u0[jnp.maximum(job, 0)],
            solver,
            jac,
        )
        return eqx.tree_at(lambda x: x.terminate, lane, lane.terminate | (job < 0))

    def advance(job, lane):
        return lane_advance(
            _at(problem, data, job // n), lane, solver, jac, max_steps, 1
        )

    def step(q: _Queue) -> _Queue:
        running = jax.vmap(lambda x: x.running(max_steps))(q.lanes)
        lanes = _select(
            running, jax.vmap(advance)(jnp.maximum(q.job, 0), q.lanes), q.lanes
        )
        done = ~jax.vmap(lambda x: x.running(max_steps))(lanes) & (q.job >= 0)
        slot = jnp.where(done, q.job, jobs)
        store = jtu.tree_map(
            lambda s, x: s.at[slot].set(x, mode="drop"), q.store, _kept(lanes)
        )
        job = jnp.where(done, q.next + jnp.cumsum(done) - 1, q.job)
        job = jnp.where(done & (job >= jobs), -1, job)
        lanes = _select(done, jax.vmap(init)(job), lanes)
        return _Queue(job, lanes, store, q.next + jnp.sum(done))

    width = num_lanes(jobs)
    first = jnp.arange(width)
    store = _kept(jax.vmap(init)(jnp.arange(jobs)))
    queue = _Queue(first, jax.vmap(init)(first), store, jnp.asarray(width))
    queue = jax.lax.while_loop(lambda q: jnp.any(q.job >= 0), step, queue)

    solved = jax.vmap(lambda j, lane: finish_at(_at(problem, data, j // n), lane, jac))(
        jnp.arange(jobs), queue.store
    )
    solved = jtu.tree_map(
        lambda x: jnp.reshape(x, (specimens, n) + x.shape[1:]), solved
    )
    return jax.vmap(
        lambda s, st, ok, out: kernel_choose(_at(problem, data, s), st, ok, out)
    )(jnp.arange(specimens), starts, start_ok, solved)
