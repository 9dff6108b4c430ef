"""Chains of the No-U-Turn sampler through a log density's gradient: BlackJAX's NUTS
kernel, vmapped over the chains, with a warm-up that adapts one step size by dual
averaging and re-estimates a dense metric from the chains' own draws.

BlackJAX is used for the kernel alone: it takes a plain log-density function of an
array, so the simulation kernel needs no probabilistic-programming wrapper, and its
kernels are pure functions that `jax.vmap` and `jax.lax.scan` compose. The warm-up is
written here because it starts from the least-squares fit's Laplace covariance (a
dense metric that is already close: the default window adaptation starts from the
identity, which on parameters whose scales differ by decades costs most of its
budget).
"""

import functools
import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from jaxtyping import Array, Float, PRNGKeyArray

from .._progress import AbstractProgressMeter, NoProgressMeter
from .methods import NUTS


# Dual averaging (Hoffman & Gelman 2014, Algorithm 5; Stan's constants).
_GAMMA = 0.05
_T0 = 10.0
_KAPPA = 0.75
# Steps per compiled call: warm-up and sampling loop over chunks of this many
# steps, so that one compiled program serves every phase and length.
CHUNK = 25
# The mean acceptance the step size aims at, and the first step size (in units of
# the metric).
TARGET_ACCEPTANCE = 0.8
INITIAL_STEP = 0.5


class _DualAveraging(eqx.Module):
    log_step: Float[Array, ""]
    log_step_bar: Float[Array, ""]
    h_bar: Float[Array, ""]
    mu: Float[Array, ""]
    count: Float[Array, ""]


def _dual_averaging_init(step_size: float) -> _DualAveraging:
    log_step = jnp.asarray(math.log(step_size))
    zero = jnp.zeros_like(log_step)
    return _DualAveraging(log_step, zero, zero, log_step + math.log(10.0), zero)


def _dual_averaging_update(
    state: _DualAveraging, acceptance: Array, target: float
) -> _DualAveraging:
    t = state.count + 1.0
    w = 1.0 / (t + _T0)
    h_bar = (1.0 - w) * state.h_bar + w * (target - acceptance)
    log_step = state.mu - jnp.sqrt(t) / _GAMMA * h_bar
    eta = t**-_KAPPA
    log_step_bar = eta * log_step + (1.0 - eta) * state.log_step_bar
    return _DualAveraging(log_step, log_step_bar, h_bar, state.mu, t)


class ChainsOut(eqx.Module):
    """The draws of one chunk: `positions` `(steps, chains, p)`, `divergent` and
    `acceptance` and `steps` (integration steps) `(steps, chains)`."""

    positions: Array
    divergent: Array
    acceptance: Array
    steps: Array


def _value_and_grad(density: Callable[[Array], Array], u):
    """The value and the forward-mode gradient of `density(u)` (see
    `logdensity_of`)."""

    def twice(v):
        value = density(v)
        return value, value

    grad, value = jax.jacfwd(twice, has_aux=True)(u)
    ok = jnp.isfinite(value) & jnp.all(jnp.isfinite(grad))
    return jnp.where(ok, value, -jnp.inf), jnp.where(ok, grad, 0.0)


@jax.custom_vjp
def _forward_density(density: Callable[[Array], Array], u):
    return _value_and_grad(density, u)[0]


def _forward_density_fwd(density, u):
    return _value_and_grad(density, u)


def _forward_density_bwd(grad, cotangent):
    # The data and the prior are not differentiated.
    return None, cotangent * grad


_forward_density.defvjp(_forward_density_fwd, _forward_density_bwd)


def logdensity_of(density: Callable[[Array], Array]) -> Callable[[Array], Array]:
    """`density` (a Module, a scalar function of a short vector u) whose gradient is
    taken in forward mode, one tangent per entry of u carried through the
    simulation's scan together: for a few parameters and thousands of samples this
    is cheaper than reverse mode, which must keep every step of the scan. A
    non-finite value reads -inf with a zero gradient, so that the sampler rejects
    the step as divergent instead of carrying NaN."""
    return lambda u: _forward_density(density, u)


@functools.cache
def make_runner(max_doublings: int):
    """The compiled chunk of NUTS steps of every chain, one per tree depth (compiled
    once per problem structure and shapes, whatever its data: the log density is an
    argument).

    **Returns:**

    `(init, run)`: `init(density, positions)` -> the chains' states (vmapped);
    `run(density, states, key, dual, inverse_mass, step_size, adapt, target)` ->
    `(states, dual, out)`, `CHUNK` steps of every chain with a shared step size:
    with `adapt`, the dual averaging state's current step size, updated from the
    chains' mean acceptance; else `step_size`.
    """
    import blackjax

    kernel = blackjax.nuts.build_kernel()

    @eqx.filter_jit
    def init(density, positions):
        logdensity = logdensity_of(density)
        return jax.vmap(lambda x: blackjax.nuts.init(x, logdensity))(positions)

    @eqx.filter_jit
    def run(density, states, key, dual, inverse_mass, step_size, adapt, target):
        logdensity = logdensity_of(density)

        def one(carry, key):
            states, dual = carry
            step = jnp.where(adapt, jnp.exp(dual.log_step), step_size)
            keys = jax.random.split(key, states.position.shape[0])
            new, info = jax.vmap(
                lambda k, s: kernel(
                    k,
                    s,
                    logdensity,
                    step,
                    inverse_mass,
                    max_num_doublings=max_doublings,
                )
            )(keys, states)
            acceptance = jnp.where(
                jnp.isfinite(info.acceptance_rate), info.acceptance_rate, 0.0
            )
            updated = _dual_averaging_update(dual, jnp.mean(acceptance), target)
            dual = jax.tree_util.tree_map(
                lambda a, b: jnp.where(adapt, a, b), updated, dual
            )
            out = ChainsOut(
                new.position, info.is_divergent, acceptance, info.num_integration_steps
            )
            return (new, dual), out

        (states, dual), out = jax.lax.scan(
            one, (states, dual), jax.random.split(key, CHUNK)
        )
        return states, dual, out

    return init, run


def _spread(positions: Array) -> Array:
    """`positions` `(chains, p)` laid out over as many of `jax.devices()` as divide
    the number of chains, one block of chains each: the vmapped chains' program is
    then partitioned by XLA over the devices (on a CPU whose cores are exposed as
    devices, `XLA_FLAGS=--xla_force_host_platform_device_count=N`, one core each).
    The draws are the same computation wherever it runs."""
    devices = jax.devices()
    count = max(d for d in range(1, len(devices) + 1) if positions.shape[0] % d == 0)
    if count == 1:
        return positions
    mesh = Mesh(np.array(devices[:count]), ("chains",))
    return jax.device_put(positions, NamedSharding(mesh, P("chains")))


def _regularised_covariance(draws: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """The within-chain covariance of `draws` `(steps, chains, p)` (the mean of each
    chain's own: chains still apart after a short warm-up would otherwise widen the
    metric by their distance, and the step size collapses), shrunk towards the
    diagonal of `fallback` as Stan shrinks towards a small identity (weight
    5 / (n + 5), n the draws): the parameters' scales differ by decades, so the
    fallback's own diagonal is the neutral target."""
    steps, chains, p = draws.shape
    per_chain = [np.cov(draws[:, c], rowvar=False).reshape(p, p) for c in range(chains)]
    cov = np.mean(per_chain, axis=0)
    n = steps * chains
    return (n / (n + 5.0)) * cov + (5.0 / (n + 5.0)) * np.diag(np.diag(fallback))


def _note(phase: str, log_step, out: ChainsOut) -> str:
    steps = float(np.mean(np.asarray(out.steps)))
    return f"{phase}: step {float(np.exp(log_step)):.3g}, {steps:.1f} steps/draw"


def run_chains(
    density: eqx.Module,
    start: Float[Array, "chains p"],
    inverse_mass: np.ndarray,
    key: PRNGKeyArray,
    method: NUTS,
    progress_meter: AbstractProgressMeter = NoProgressMeter(),
) -> dict:
    """Warm-up and sampling of the chains.

    Warm-up, in chunks of `CHUNK` steps (`num_warmup` rounded up): the first half
    adapts the step size with the given metric; the metric is then re-estimated as
    the within-chain covariance of the draws of the second quarter, and the
    second half adapts the step size again with it. Sampling keeps the final
    step size (dual averaging's averaged iterate) and metric.

    **Arguments:**

    - `density`: the log density of the unconstrained parameters, a Module called
        with u.
    - `start`: each chain's first position.
    - `inverse_mass`: the initial metric, `(p, p)` (the Laplace covariance).
    - `key`: the random key.
    - `method`: the sampler's settings: `num_warmup`, `num_samples` (steps of each
        chain) and `max_doublings` (the largest tree depth of NUTS, 2^depth - 1
        steps). The step size aims at the mean acceptance `TARGET_ACCEPTANCE` from
        `INITIAL_STEP` (in units of the metric).
    - `progress_meter`: how to show progress (one step per chunk).

    **Returns:**

    A dict: `draws` `(chains, num_samples, p)`, `divergent` (count over the sampling
    phase), `acceptance` (mean), `step_size`, `inverse_mass`, `mean_steps`
    (integration steps per draw).
    """
    num_warmup, num_samples = method.num_warmup, method.num_samples
    target = TARGET_ACCEPTANCE
    init, run = make_runner(method.max_doublings)
    start = _spread(jnp.asarray(start))
    states = init(density, start)
    ok = np.isfinite(np.asarray(states.logdensity))
    if not np.all(ok):
        # A chain whose start is outside the model's domain starts where the first
        # valid one does.
        if not np.any(ok):
            raise ValueError("no chain's start has a finite posterior density.")
        fixed = np.where(ok[:, None], np.asarray(start), np.asarray(start)[ok][0])
        states = init(density, _spread(jnp.asarray(fixed)))
    chunks = max(2, -(-num_warmup // CHUNK))
    first = chunks // 2
    dual = _dual_averaging_init(INITIAL_STEP)
    mass = jnp.asarray(inverse_mass)
    keys = jax.random.split(key, chunks + max(1, -(-num_samples // CHUNK)))
    never = jnp.asarray(1.0)
    history = []
    with progress_meter.bar("NUTS", len(keys), eta=True) as meter:
        for i in range(chunks):
            if i == first:
                # The second quarter of the warm-up has left the start behind.
                window = np.concatenate(history[first // 2 :], axis=0)
                mass = jnp.asarray(_regularised_covariance(window, np.asarray(mass)))
                dual = _dual_averaging_init(float(np.exp(dual.log_step_bar)))
            states, dual, out = run(
                density, states, keys[i], dual, mass, never, jnp.asarray(True), target
            )
            history.append(np.asarray(out.positions))
            meter.advance(note=_note("warm-up", dual.log_step, out))
        step_size = jnp.exp(dual.log_step_bar)
        draws, divergent, acceptance, steps = [], 0, [], []
        for i in range(chunks, len(keys)):
            states, dual, out = run(
                density,
                states,
                keys[i],
                dual,
                mass,
                step_size,
                jnp.asarray(False),
                target,
            )
            draws.append(np.asarray(out.positions))
            divergent += int(np.sum(np.asarray(out.divergent)))
            acceptance.append(np.asarray(out.acceptance))
            steps.append(np.asarray(out.steps))
            meter.advance(note=_note("sampling", jnp.log(step_size), out))
    draws = np.concatenate(draws, axis=0)[:num_samples]
    return {
        "draws": np.swapaxes(draws, 0, 1),
        "divergent": divergent,
        "acceptance": float(np.mean(np.concatenate(acceptance))),
        "step_size": float(step_size),
        "inverse_mass": np.asarray(mass),
        "mean_steps": float(np.mean(np.concatenate(steps))),
    }
