"""The Monte-Carlo of cable sets: parameter draws x cables x load histories, chunked
over the draws, sharded over devices, reduced to percentiles of elongation over time
(`monte_carlo`, returning a `MonteCarloResult`)."""

import warnings
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from jaxtyping import Array, Float, Int, PRNGKeyArray

from .._cable import Cable
from .._drive import Protocol
from .._progress import (
    AbstractProgressMeter,
    TextProgressMeter,
    check_progress_meter,
)
from .inputs import (
    ForceHistory,
    check_cables,
    check_devices,
    check_int,
    check_key,
    check_loads,
    check_percentiles,
)
from .samplers import AbstractParameterSampler
from .sharding import (
    AXIS,
    STATUS_NAMES,
    chunk_step,
    empty_statistics,
    global_array,
    to_host,
)
from .streaming import (
    histogram_edges,
    merge_devices,
    percentiles_from_draws,
    percentiles_from_histogram,
)


# `method="auto"` keeps every draw (exact percentiles) up to this many values.
_EXACT_LIMIT = 2**24
# Default chunk: about this many elongation values per device (bounded memory).
_CHUNK_VALUES = 2**23
# Refuse histograms above this many bytes per device.
_HISTOGRAM_LIMIT = 4 * 2**30


class MonteCarloResult(eqx.Module):
    """Statistics of elongation over time, per cable, over the successful draws.

    **Fields:**

    - `q`: the percentile levels, in percent (as `numpy.percentile`), shape `(q,)`.
    - `time`: sample times, s, shape `(cables, samples)`: the given times of a
        [`jaxcable.ForceHistory`][]; for a rate-driven [`jaxcable.Protocol`][] (whose
        times are solved per draw) the mean solved time over the successful draws.
        Statistics are per sample index (e.g. per force sample of a protocol).
    - `percentiles`: elongation percentiles, m, shape `(q, cables, samples)`.
    - `resolution`: a bound on the absolute error of each percentile, m, same shape:
        0 with `method="exact"`; the width of the histogram bins that hold the
        order statistics with `method="histogram"`.
    - `mean`, `std`, `min`, `max`: exact elongation statistics, m, shape
        `(cables, samples)` (std with ddof=0).
    - `num_draws`: the number of draws.
    - `num_successful`: successful draws per cable, shape `(cables,)`; the statistics
        use these only.
    - `num_broken`: per cable, shape `(cables,)`, the draws whose cable was strained
        beyond its breaking strain (`Cable.breaking_strain`) before any other
        failure: `status_counts["strain_beyond_break"]`. These draws are excluded
        from the statistics like any failure; a high count says that the loads
        break the cable for that share of the drawn parameters.
    - `status_counts`: `{RESULTS member name: count per cable}`; they sum to
        `num_draws` for every cable. A draw that fails for one cable (e.g. a Newton
        solve that does not converge) is excluded for that cable only.
    - `method`: `"exact"` or `"histogram"`.
    - `elongation`: every draw's elongation, m, shape `(draws, cables, samples)`, with
        NaN where the draw failed; only with `method="exact"` and `keep_draws=True`,
        else None.
    """

    q: Float[Array, " q"]
    time: Float[Array, "cables samples"]
    percentiles: Float[Array, "q cables samples"]
    resolution: Float[Array, "q cables samples"]
    mean: Float[Array, "cables samples"]
    std: Float[Array, "cables samples"]
    min: Float[Array, "cables samples"]
    max: Float[Array, "cables samples"]
    num_draws: int = eqx.field(static=True)
    num_successful: Int[Array, " cables"]
    num_broken: Int[Array, " cables"]
    status_counts: dict[str, Int[Array, " cables"]]
    method: str = eqx.field(static=True)
    elongation: Float[Array, "draws cables samples"] | None = None

    def percentile(self, q: float) -> Float[Array, "cables samples"]:
        """The elongation percentile `q` (one of `self.q`, in percent), m.

        **Arguments:**

        - `q`: the percentile level, in percent.

        **Returns:**

        An array of shape `(cables, samples)`.
        """
        levels = np.asarray(self.q, dtype=float)
        hit = np.flatnonzero(np.isclose(levels, q, rtol=0, atol=1e-9))
        if hit.size == 0:
            raise ValueError(
                f"`q`={q} was not computed; the result holds the percentiles "
                f"{levels.tolist()}."
            )
        return self.percentiles[int(hit[0])]


def monte_carlo(
    parameters: AbstractParameterSampler,
    cables: Cable,
    loads: Protocol | ForceHistory,
    *,
    key: PRNGKeyArray,
    num_draws: int,
    percentiles: Sequence[float] = (1.0, 5.0, 50.0, 95.0, 99.0),
    chunk_size: int | None = None,
    method: str = "auto",
    bins: int = 1024,
    keep_draws: bool = False,
    devices: Sequence[jax.Device] | None = None,
    progress_meter: AbstractProgressMeter | None = None,
) -> MonteCarloResult:
    """Monte-Carlo of a set of cables over parameter draws: percentiles of elongation
    over time.

    Each draw is one parameter set (from `parameters`), shared by all cables (the 8
    cables of a CDPR cut from one spool); every (draw, cable) pair is simulated with the
    cable's length, speed and load history, all in one jitted `vmap`. Draws run in
    chunks of `chunk_size` (one compiled function called once per chunk with the same
    shapes; the last chunk is padded with draws that are discarded), so memory is
    bounded whatever `num_draws` is. Draw i uses the key `jax.random.fold_in(key, i)`:
    results are reproducible and do not depend on `chunk_size` or on the devices.

    A (draw, cable) whose simulation fails (`RESULTS` other than `successful`, e.g. a
    Newton solve that does not converge, or a drawn parameter outside its domain) is
    counted in `status_counts` and excluded from that cable's statistics. A draw
    that strains a cable beyond its breaking strain (`Cable.breaking_strain`) is
    such a failure, `RESULTS.strain_beyond_break`, and is also counted in
    `num_broken`.

    **Percentiles in bounded memory.** `method="exact"` keeps every draw on the host
    (draws x cables x samples values) and calls `numpy.percentile`. `method="histogram"`
    keeps, per (cable, sample), a histogram of `bins` equal bins over the range of the
    first chunk widened by half of it on each side, plus an underflow and an overflow
    bin bounded by the exact running minimum and maximum; a percentile is interpolated
    within the bins that hold its order statistics, and `resolution` bounds its
    absolute error (the width of those bins, 2 x range(first chunk) / `bins`: ~2e-3
    of the spread with the default 1024 bins; larger only where a percentile falls in
    the under- or overflow bin, i.e. beyond 1.5 x the first chunk's range, which
    `resolution` then shows). Mean, std, min and max are exact
    in both (Welford's running update per device, merged
    across devices with Chan's formula). `"auto"` is `"exact"` up to
    2**24 stored values, else `"histogram"`.

    **Devices.** The draws of a chunk are sharded over `devices` (default
    `jax.devices()`: every visible device, on every host) with `jax.shard_map` on a
    one-axis `Mesh`; each device runs its share and keeps its own statistics, merged
    once at the end. On one device this is a no-op. On a CPU, XLA runs one scan on one
    core: `XLA_FLAGS=--xla_force_host_platform_device_count=N` (set before importing
    jax) exposes N CPU devices and spreads the draws over N cores.

    **Several processes or hosts.** Start the same script in every process with
    `jax.distributed.initialize(coordinator_address, num_processes, process_id)` first
    (on Slurm/TPU pods it needs no arguments), before importing jaxcable (whose import
    already creates arrays, i.e. jax's backend); `jax.devices()` then lists the devices
    of all processes, each runs the draws of its own devices, and every process
    receives the same full result. All processes must call `monte_carlo` with the same
    arguments (same key). `scripts/montecarlo_distributed.py` is such a launcher
    (gloo CPU collectives, bounded waits); `tests/test_distributed.py` checks that 2
    processes on 127.0.0.1 give the single-process result.

    **Arguments:**

    - `parameters`: an [`jaxcable.AbstractParameterSampler`][]:
        [`jaxcable.IndependentParameters`][] (per-parameter distributions) or
        [`jaxcable.CorrelatedParameters`][] (a fit's mean and covariance).
    - `cables`: a [`jaxcable.Cable`][] whose fields have shape `(cables,)` (or are
        scalars: one cable).
    - `loads`: a [`jaxcable.ForceHistory`][] (time-stamped forces) or a
        [`jaxcable.Protocol`][] (a rate-driven test), of shape `(samples,)` (shared) or
        `(cables, samples)` (for protocols: stack equal-length ones, see
        [`jaxcable.Protocol.pad`][], with
        `jax.tree_util.tree_map(lambda *a: jnp.stack(a), *protocols)`).
    - `key`: a JAX PRNG key (`jax.random.key(seed)`); no default, for reproducibility.
    - `num_draws`: the number of parameter draws.
    - `percentiles`: the percentile levels to compute, in percent (0-100).
    - `chunk_size`: draws per chunk (rounded up to a multiple of the number of
        devices); default about 2**23 / (cables x samples) per device.
    - `method`: `"auto"`, `"exact"` or `"histogram"` (see above).
    - `bins`: histogram bins per (cable, sample) (`method="histogram"`).
    - `keep_draws`: with `method="exact"`, return every draw in `elongation`.
    - `devices`: the devices to shard the draws over (default `jax.devices()`).
    - `progress_meter`: how progress is shown (default
        [`jaxcable.TextProgressMeter`][]: a bar on stderr, kept at the end;
        [`jaxcable.NoProgressMeter`][]: nothing).

    **Returns:**

    A [`jaxcable.MonteCarloResult`][] (elongations in m, times in s).
    """
    if not isinstance(parameters, AbstractParameterSampler):
        raise ValueError(
            "`parameters` must be a jaxcable parameter sampler (IndependentParameters "
            f"or CorrelatedParameters), got {type(parameters).__name__}."
        )
    key = check_key(key)
    num_draws = check_int("num_draws", num_draws, 1)
    q = check_percentiles(percentiles)
    if method not in ("auto", "exact", "histogram"):
        raise ValueError(
            f"`method` must be 'auto', 'exact' or 'histogram', got {method!r}."
        )
    bins = check_int("bins", bins, 2)
    meter = check_progress_meter(progress_meter, TextProgressMeter())
    cables = check_cables(cables)
    loads, load_axis, samples = check_loads(loads, cables)
    ncables = cables.length.shape[0]
    dtype = cables.length.dtype

    devices = check_devices(devices)
    ndev = len(devices)
    per_draw = ncables * samples
    if chunk_size is None:
        # About 2**23 values per device and chunk (32 MiB of float32 elongations).
        chunk_size = max(1, _CHUNK_VALUES // per_draw) * ndev
    chunk_size = check_int("chunk_size", chunk_size, 1)
    chunk_size = min(chunk_size, num_draws)
    chunk = -(-chunk_size // ndev) * ndev
    local = chunk // ndev
    num_chunks = -(-num_draws // chunk)

    if method == "auto":
        method = "exact" if num_draws * per_draw <= _EXACT_LIMIT else "histogram"
    if keep_draws and method != "exact":
        raise ValueError("`keep_draws=True` needs `method='exact'`.")
    exact = method == "exact"
    hist_bins = 0 if exact else bins
    if hist_bins and per_draw * (hist_bins + 2) * 4 > _HISTOGRAM_LIMIT:
        raise ValueError(
            f"`bins`={bins} makes a histogram of {per_draw * (bins + 2) * 4 / 2**30:.1f} "
            "GiB per device for this many cables x samples; use fewer bins."
        )

    mesh = Mesh(np.asarray(devices), (AXIS,))
    replicated = NamedSharding(mesh, P())
    step = chunk_step(
        mesh, local, load_axis, hist_bins, exact, jax.random.key_impl(key)
    )

    # Every input becomes a global array replicated over the mesh (on several hosts,
    # every process passes the same values).
    dyn, static = eqx.partition((parameters, cables, loads), eqx.is_array)
    dyn = jax.tree_util.tree_map(lambda x: global_array(x, replicated), dyn)
    parameters, cables, loads = eqx.combine(dyn, static)
    key_data = global_array(jax.random.key_data(key), replicated)
    total = global_array(np.int32(num_draws), replicated)

    def run(c, stats, lo, width):
        start = global_array(np.int32(c * chunk), replicated)
        return step(parameters, cables, loads, key_data, start, total, stats, lo, width)

    def put(x):
        return global_array(np.asarray(x, dtype), replicated)

    def fresh():
        return empty_statistics(mesh, ncables, samples, hist_bins, dtype)

    lo = np.zeros((ncables, samples), dtype)
    width = np.ones((ncables, samples), dtype)
    if hist_bins:
        # The bins are set by the range of the first chunk: it is run once more (same
        # compiled function) and only its exact minimum and maximum are kept.
        probe = run(0, fresh(), put(lo), put(width))
        lo, width = histogram_edges(
            to_host(probe.minimum).min(axis=0),
            to_host(probe.maximum).max(axis=0),
            hist_bins,
            dtype,
        )
    lo_dev, width_dev = put(lo), put(width)

    kept = kept_valid = None
    if exact:
        kept = np.empty((num_chunks * chunk, ncables, samples), np.dtype(dtype))
        kept_valid = np.empty((num_chunks * chunk, ncables), bool)
    stats = fresh()
    with meter.bar("monte_carlo", num_chunks, eta=True, keep=True) as bar:
        for c in range(num_chunks):
            out = run(c, stats, lo_dev, width_dev)
            if exact:
                stats, elongation, valid = out
                kept[c * chunk : (c + 1) * chunk] = to_host(elongation)
                kept_valid[c * chunk : (c + 1) * chunk] = to_host(valid)
            else:
                stats = jax.block_until_ready(out)
            bar.advance(note=f"{min((c + 1) * chunk, num_draws)}/{num_draws} draws")

    merged = merge_devices(jax.tree_util.tree_map(to_host, stats))
    n_ok = merged.status[STATUS_NAMES.index("successful")]
    none = n_ok == 0
    if np.any(none):
        warnings.warn(
            f"monte_carlo: no successful draw for cables {np.flatnonzero(none).tolist()}; "
            "their statistics are NaN (see `status_counts`).",
            stacklevel=2,
        )
    nan_if_none = lambda a: np.where(none[:, None], np.nan, a)

    if exact:
        kept, kept_valid = kept[:num_draws], kept_valid[:num_draws]
        values = percentiles_from_draws(kept, kept_valid, q)
        resolution = np.where(np.isnan(values), np.nan, 0.0)
        if keep_draws:
            kept = np.where(kept_valid[:, :, None], kept, np.nan)
    else:
        hist = merged.histogram.reshape(ncables, samples, hist_bins + 2)
        cnt = np.broadcast_to(n_ok[:, None], (ncables, samples))
        values, resolution = percentiles_from_histogram(
            hist,
            lo.astype(float),
            width.astype(float),
            merged.minimum,
            merged.maximum,
            cnt,
            q,
        )
        values = np.where(none[None, :, None], np.nan, values)
        resolution = np.where(none[None, :, None], np.nan, resolution)

    if isinstance(loads, ForceHistory):
        time = np.broadcast_to(np.asarray(loads.time), (ncables, samples))
    else:
        time = nan_if_none(merged.time_mean)
    std = np.sqrt(merged.m2 / np.maximum(merged.count, 1.0)[:, None])
    as_dtype = lambda a: jnp.asarray(np.asarray(a), dtype)
    return MonteCarloResult(
        q=as_dtype(q),
        time=as_dtype(time),
        percentiles=as_dtype(values),
        resolution=as_dtype(resolution),
        mean=as_dtype(nan_if_none(merged.mean)),
        std=as_dtype(nan_if_none(std)),
        min=as_dtype(nan_if_none(merged.minimum)),
        max=as_dtype(nan_if_none(merged.maximum)),
        num_draws=num_draws,
        num_successful=jnp.asarray(n_ok),
        num_broken=jnp.asarray(
            merged.status[STATUS_NAMES.index("strain_beyond_break")]
        ),
        status_counts={
            n: jnp.asarray(status) for n, status in zip(STATUS_NAMES, merged.status)
        },
        method=method,
        elongation=as_dtype(kept) if keep_draws else None,
    )
