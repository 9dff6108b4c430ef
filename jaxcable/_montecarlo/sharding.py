"""Where the draws run: the one-axis device mesh, the compiled chunk function (draw the
parameters, simulate every (draw, cable) pair, fold the results into each device's
statistics), and the moves of arrays between the host and the devices of one or
several hosts."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from jaxtyping import Array

from .._drive import Protocol, Simulation, simulate_force_history, simulate_rate_test
from .._results import RESULTS
from .streaming import Statistics, update


# The mesh's one axis: the draws of a chunk are split over it.
AXIS = "draws"
# The `RESULTS` member names, in the order of `Statistics.status`; equinox keeps an
# Enumeration's members in this mapping and has no public list of them.
STATUS_NAMES = tuple(RESULTS._name_to_item)
# A draw's failure is counted, not raised.
_QUIET = Simulation(throw=False)


def _simulate_one(model, cable, load):
    if isinstance(load, Protocol):
        traj = simulate_rate_test(model, cable, load, method=_QUIET)
    else:
        traj = simulate_force_history(
            model, cable, load.time, load.force, mask=load.mask, method=_QUIET
        )
    return traj.elongation, traj.time, traj.result


def _local_draws(parameters, cables, loads, key, start, num_draws, local, load_axis):
    # This device's `local` draws of the chunk that starts at draw `start`; draw i
    # uses the key fold_in(key, i), whatever the chunk and the device.
    device = jax.lax.axis_index(AXIS)
    index = start + device * local + jnp.arange(local)
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(index)
    models = jax.vmap(parameters.draw)(keys)

    def per_draw(model):
        return jax.vmap(
            lambda c, ld: _simulate_one(model, c, ld), in_axes=(0, load_axis)
        )(cables, loads)

    elongation, time, result = eqx.filter_vmap(per_draw)(models)
    # The padding draws past `num_draws` (in the last chunk) count nowhere.
    real = index < num_draws
    valid = (result == RESULTS.successful) & real[:, None]
    status = jnp.stack(
        [
            jnp.sum(
                (result == RESULTS._name_to_item[n]) & real[:, None],
                axis=0,
                dtype=jnp.int32,
            )
            for n in STATUS_NAMES
        ]
    )
    return elongation, time, valid, status


@functools.lru_cache(maxsize=32)
def chunk_step(mesh: Mesh, local: int, load_axis, bins: int, keep: bool, impl: str):
    """The jitted chunk function of one Monte-Carlo configuration: compiled once, then
    called once per chunk with the same shapes.

    **Arguments:**

    - `mesh`: the one-axis device mesh (axis `AXIS`).
    - `local`: draws per device and chunk.
    - `load_axis`: the cable axis of the loads' arrays (0, or None when shared).
    - `bins`: histogram bins (0: no histogram).
    - `keep`: also return every draw's elongation and validity (exact percentiles).
    - `impl`: the PRNG implementation of the key.

    **Returns:**

    A function `step(parameters, cables, loads, key, start, num_draws, stats, lo,
    width)` of global arrays (`key` as raw key data, `start` the chunk's first draw)
    that returns the updated `Statistics`, or with `keep` the triple
    `(stats, elongation, valid)`.
    """
    spec = P(AXIS)

    @eqx.filter_jit
    def step(parameters, cables, loads, key, start, num_draws, stats, lo, width):
        dyn, static = eqx.partition((parameters, cables, loads), eqx.is_array)

        def per_device(dyn, key, start, num_draws, stats, lo, width):
            parameters, cables, loads = eqx.combine(dyn, static)
            # The key travels as raw key data (a plain global array on every host).
            key = jax.random.wrap_key_data(key, impl=impl)
            elongation, time, valid, status = _local_draws(
                parameters, cables, loads, key, start, num_draws, local, load_axis
            )
            # Only a rate-driven test has solved (per-draw) times to average.
            if not isinstance(loads, Protocol):
                time = None
            stats = update(stats, elongation, time, valid, status, lo, width, bins)
            return (stats, elongation, valid) if keep else stats

        return jax.shard_map(
            per_device,
            mesh=mesh,
            in_specs=(P(), P(), P(), P(), spec, P(), P()),
            out_specs=(spec, spec, spec) if keep else spec,
            check_vma=False,
        )(dyn, key, start, num_draws, stats, lo, width)

    return step


def global_array(x, sharding) -> Array:
    """A host NumPy array as a global jax array laid out by `sharding`: each process
    places the shards of its own devices (the same call on one or several hosts)."""
    x = np.asarray(x)
    return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])


def to_host(x) -> np.ndarray:
    """A global array as a NumPy array on this process (all-gathered across hosts)."""
    if getattr(x, "is_fully_addressable", True):
        return np.asarray(x)
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(x, tiled=True))


def empty_statistics(
    mesh: Mesh, ncables: int, samples: int, bins: int, dtype
) -> Statistics:
    """Every device's statistics before the first draw, sharded over the mesh.

    **Arguments:**

    - `mesh`: the one-axis device mesh.
    - `ncables`, `samples`: the number of cables and of samples per load.
    - `bins`: histogram bins (0: no histogram).
    - `dtype`: the simulation's dtype.

    **Returns:**

    A `Statistics` with a leading device axis: zero counts and moments, +-inf
    extremes.
    """
    sharding = NamedSharding(mesh, P(AXIS))

    def full(shape, dt=dtype, fill: float = 0):
        return global_array(np.full((mesh.size, *shape), fill, dt), sharding)

    return Statistics(
        count=full((ncables,)),
        mean=full((ncables, samples)),
        m2=full((ncables, samples)),
        time_mean=full((ncables, samples)),
        minimum=full((ncables, samples), fill=np.inf),
        maximum=full((ncables, samples), fill=-np.inf),
        status=full((len(STATUS_NAMES), ncables), jnp.int32),
        histogram=full((ncables * samples * (bins + 2) if bins else 1,), jnp.int32),
    )
