"""The Monte-Carlo of cable sets: parameter draws x cables x load histories, chunked
over the draws, sharded over devices, reduced to percentiles of elongation over time
(`monte_carlo`, returning a `MonteCarloResult`)."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from jaxtyping import Array, Float, Int

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
    check_loads,
    check_percentiles,
)
from .method import MonteCarlo
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
    method: MonteCarlo,
    *,
    progress_meter: AbstractProgressMeter | None = None,
) -> MonteCarloResult:
    """Monte-Carlo of a set of cables over parameter draws: percentiles of elongation
    over time.

    Each draw is one parameter set (from `parameters`), shared by all cables (the 8
    cables of a CDPR cut from one spool); every (draw, cable) pair is simulated with the
    cable's length, speed and load history, all in one jitted `vmap`. Draws run in
    chunks of `method.chunk_size` (one compiled function called once per chunk with the same
    shapes; the last chunk is padded with draws that are discarded), so memory is
    bounded whatever the number of draws is. Draw i uses the key `jax.random.fold_in(method.key, i)`:
    results are reproducible and do not depend on `chunk_size` or on the devices.

    A (draw, cable) whose simulation fails (`RESULTS` other than `successful`, e.g. a
    Newton solve that does not converge, or a drawn parameter outside its domain) is
    counted in `status_counts` and excluded from that cable's statistics. A draw
    that strains a cable beyond its breaking strain (`Cable.breaking_strain`) is
    such a failure, `RESULTS.strain_beyond_break`, and is also counted in
    `num_broken`.

    **Percentiles in bounded memory.** `MonteCarlo(method="exact")` keeps every draw on the host
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

    **Devices.** The draws of a chunk are sharded over `method.devices` (default
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
    - `method`: a [`jaxcable.MonteCarlo`][]: the number of draws and their key, the
        percentile levels, the chunk size, `method` (`"auto"`, `"exact"` or
        `"histogram"`, see above), the histogram's bins, whether to keep every draw
        and the devices.
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
    if not isinstance(method, MonteCarlo):
        raise TypeError(
            f"`method` must be a jaxcable.MonteCarlo, got {type(method).__name__}."
        )
    meter = check_progress_meter(progress_meter, TextProgressMeter())
    cables = check_cables(cables)
    loads, load_axis, samples = check_loads(loads, cables)
    plan = _Plan.make(method, cables.length.shape[0], samples, cables.length.dtype)
    mesh = Mesh(np.asarray(plan.devices), (AXIS,))
    replicated = NamedSharding(mesh, P())
    step = chunk_step(
        mesh,
        plan.local,
        load_axis,
        plan.hist_bins,
        plan.exact,
        jax.random.key_impl(method.key),
    )
    # Every input becomes a global array replicated over the mesh (on several hosts,
    # every process passes the same values).
    dyn, static = eqx.partition((parameters, cables, loads), eqx.is_array)
    dyn = jax.tree_util.tree_map(lambda x: global_array(x, replicated), dyn)
    parameters, cables, loads = eqx.combine(dyn, static)
    key_data = global_array(jax.random.key_data(method.key), replicated)
    total = global_array(np.int32(plan.num_draws), replicated)

    def run(c, stats, lo, width):
        start = global_array(np.int32(c * plan.chunk), replicated)
        return step(parameters, cables, loads, key_data, start, total, stats, lo, width)

    def put(x):
        return global_array(np.asarray(x, plan.dtype), replicated)

    def fresh():
        return empty_statistics(
            mesh, plan.ncables, plan.samples, plan.hist_bins, plan.dtype
        )

    lo, width = _bins(plan, run, fresh, put)
    stats, kept, kept_valid = _run_chunks(
        plan, meter, run, fresh(), put(lo), put(width)
    )
    merged = merge_devices(jax.tree_util.tree_map(to_host, stats))
    times = np.asarray(loads.time) if isinstance(loads, ForceHistory) else None
    return _result(plan, merged, (kept, kept_valid), (lo, width), times)


class _Plan(eqx.Module):
    """The shapes and choices of one Monte-Carlo: `num_draws`, the draws per
    `chunk` and per device (`local`), `num_chunks`, the `ncables` x `samples`
    values per draw, the `dtype`, the percentile levels `q`, the `method` (`"exact"`
    or `"histogram"`, `exact`, `hist_bins`: 0 when exact), `keep_draws` and the
    `devices`."""

    num_draws: int
    chunk: int
    local: int
    num_chunks: int
    ncables: int
    samples: int
    dtype: np.dtype
    q: np.ndarray
    method: str
    exact: bool
    hist_bins: int
    keep_draws: bool
    devices: list

    @staticmethod
    def make(method: MonteCarlo, ncables: int, samples: int, dtype) -> "_Plan":
        """The plan of `method` for `ncables` x `samples` values per draw."""
        num_draws = method.num_draws
        devices = check_devices(method.devices)
        ndev = len(devices)
        per_draw = ncables * samples
        chunk_size = method.chunk_size
        if chunk_size is None:
            # About 2**23 values per device and chunk (32 MiB of float32 elongations).
            chunk_size = max(1, _CHUNK_VALUES // per_draw) * ndev
        chunk_size = min(chunk_size, num_draws)
        chunk = -(-chunk_size // ndev) * ndev
        statistics = method.method
        if statistics == "auto":
            exact_fits = num_draws * per_draw <= _EXACT_LIMIT
            statistics = "exact" if exact_fits else "histogram"
        if method.keep_draws and statistics != "exact":
            raise ValueError("`keep_draws=True` needs `method='exact'`.")
        exact = statistics == "exact"
        hist_bins = 0 if exact else method.bins
        if hist_bins and per_draw * (hist_bins + 2) * 4 > _HISTOGRAM_LIMIT:
            raise ValueError(
                f"`bins`={method.bins} makes a histogram of "
                f"{per_draw * (method.bins + 2) * 4 / 2**30:.1f} GiB per device for "
                "this many cables x samples; use fewer bins."
            )
        return _Plan(
            num_draws=num_draws,
            chunk=chunk,
            local=chunk // ndev,
            num_chunks=-(-num_draws // chunk),
            ncables=ncables,
            samples=samples,
            dtype=dtype,
            q=check_percentiles(method.percentiles),
            method=statistics,
            exact=exact,
            hist_bins=hist_bins,
            keep_draws=method.keep_draws,
            devices=devices,
        )


def _bins(plan: _Plan, run, fresh, put):
    """The histogram's lower edges and bin widths per (cable, sample), set by the
    range of the first chunk (run once more, the same compiled function, keeping
    only its exact minimum and maximum); zeros and ones when exact."""
    lo = np.zeros((plan.ncables, plan.samples), plan.dtype)
    width = np.ones((plan.ncables, plan.samples), plan.dtype)
    if not plan.hist_bins:
        return lo, width
    probe = run(0, fresh(), put(lo), put(width))
    return histogram_edges(
        to_host(probe.minimum).min(axis=0),
        to_host(probe.maximum).max(axis=0),
        plan.hist_bins,
        plan.dtype,
    )


def _run_chunks(plan: _Plan, meter, run, stats, lo_dev, width_dev):
    """Every chunk in turn: the statistics, and with exact percentiles every draw's
    elongation and validity on the host (else None, None)."""
    kept = kept_valid = None
    if plan.exact:
        rows = plan.num_chunks * plan.chunk
        kept = np.empty((rows, plan.ncables, plan.samples), np.dtype(plan.dtype))
        kept_valid = np.empty((rows, plan.ncables), bool)
    chunk, num_draws = plan.chunk, plan.num_draws
    with meter.bar("monte_carlo", plan.num_chunks, eta=True, keep=True) as bar:
        for c in range(plan.num_chunks):
            out = run(c, stats, lo_dev, width_dev)
            if kept is not None and kept_valid is not None:  # exact percentiles
                stats, elongation, valid = out
                kept[c * chunk : (c + 1) * chunk] = to_host(elongation)
                kept_valid[c * chunk : (c + 1) * chunk] = to_host(valid)
            else:
                stats = jax.block_until_ready(out)
            bar.advance(note=f"{min((c + 1) * chunk, num_draws)}/{num_draws} draws")
    return stats, kept, kept_valid


def _result(plan: _Plan, merged, draws, edges, times) -> MonteCarloResult:
    """The [`jaxcable.MonteCarloResult`][] from the merged statistics, the kept
    `draws` (elongations and validity, or None), the histogram's `edges` (lower
    edges and widths) and the given `times` of a force history (None: a protocol's
    mean solved times)."""
    n_ok = merged.status[STATUS_NAMES.index("successful")]
    none = n_ok == 0
    if np.any(none):
        warnings.warn(
            f"monte_carlo: no successful draw for cables {np.flatnonzero(none).tolist()}; "
            "their statistics are NaN (see `status_counts`).",
            stacklevel=3,
        )
    nan_if_none = lambda a: np.where(none[:, None], np.nan, a)
    values, resolution, kept = _percentiles(plan, merged, draws, edges, n_ok)
    shape = (plan.ncables, plan.samples)
    if times is not None:
        time = np.broadcast_to(times, shape)
    else:
        time = nan_if_none(merged.time_mean)
    std = np.sqrt(merged.m2 / np.maximum(merged.count, 1.0)[:, None])
    as_dtype = lambda a: jnp.asarray(np.asarray(a), plan.dtype)
    return MonteCarloResult(
        q=as_dtype(plan.q),
        time=as_dtype(time),
        percentiles=as_dtype(values),
        resolution=as_dtype(resolution),
        mean=as_dtype(nan_if_none(merged.mean)),
        std=as_dtype(nan_if_none(std)),
        min=as_dtype(nan_if_none(merged.minimum)),
        max=as_dtype(nan_if_none(merged.maximum)),
        num_draws=plan.num_draws,
        num_successful=jnp.asarray(n_ok),
        num_broken=jnp.asarray(
            merged.status[STATUS_NAMES.index("strain_beyond_break")]
        ),
        status_counts={
            n: jnp.asarray(status) for n, status in zip(STATUS_NAMES, merged.status)
        },
        method=plan.method,
        elongation=as_dtype(kept) if plan.keep_draws else None,
    )


def _percentiles(plan: _Plan, merged, draws, edges, n_ok):
    """The percentiles, their resolution and the kept draws (NaN where failed)."""
    none = n_ok == 0
    kept, kept_valid = draws
    if plan.exact:
        kept, kept_valid = kept[: plan.num_draws], kept_valid[: plan.num_draws]
        values = percentiles_from_draws(kept, kept_valid, plan.q)
        resolution = np.where(np.isnan(values), np.nan, 0.0)
        if plan.keep_draws:
            kept = np.where(kept_valid[:, :, None], kept, np.nan)
        return values, resolution, kept
    lo, width = edges
    shape = (plan.ncables, plan.samples)
    hist = merged.histogram.reshape(*shape, plan.hist_bins + 2)
    values, resolution = percentiles_from_histogram(
        hist,
        lo.astype(float),
        width.astype(float),
        merged.minimum,
        merged.maximum,
        np.broadcast_to(n_ok[:, None], shape),
        plan.q,
    )
    values = np.where(none[None, :, None], np.nan, values)
    resolution = np.where(none[None, :, None], np.nan, resolution)
    return values, resolution, kept
