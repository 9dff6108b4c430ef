"""Streamed statistics of a Monte-Carlo in bounded memory: running moments, extremes,
status counts and per-(cable, sample) histograms folded in one draw at a time on each
device, merged across devices on the host, and the percentiles read from them."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int


class Statistics(eqx.Module):
    """Running statistics of the elongations of the successful draws.

    Between chunks every field has a leading device axis (sharded over the mesh: each
    device keeps its own); inside one device's loop over its draws, and once merged on
    the host (see `merge_devices`), it has none.

    **Fields:**

    - `count`: successful draws per cable.
    - `mean`, `m2`: Welford's running mean and sum of squared deviations of the
        elongation, per (cable, sample).
    - `time_mean`: the running mean of the solved sample times (rate-driven tests).
    - `minimum`, `maximum`: the exact extremes, per (cable, sample).
    - `status`: draws per `RESULTS` member and cable.
    - `histogram`: `bins + 2` counts per (cable, sample), flattened (one placeholder
        cell when no histogram is kept).
    """

    count: Float[Array, "*dev cables"]
    mean: Float[Array, "*dev cables samples"]
    m2: Float[Array, "*dev cables samples"]
    time_mean: Float[Array, "*dev cables samples"]
    minimum: Float[Array, "*dev cables samples"]
    maximum: Float[Array, "*dev cables samples"]
    status: Int[Array, "*dev status cables"]
    histogram: Int[Array, "*dev cells"]


def update(
    stats: Statistics,
    elongation: Float[Array, "draws cables samples"],
    time: Float[Array, "draws cables samples"] | None,
    valid: Bool[Array, "draws cables"],
    status: Int[Array, "status cables"],
    lo: Float[Array, "cables samples"],
    width: Float[Array, "cables samples"],
    bins: int,
) -> Statistics:
    """Fold one device's chunk of draws into its statistics, one draw at a time.

    Welford's update (numerically stable in float32 over 10^6 draws) over the draws in
    a `fori_loop`: each step reads one contiguous (cables, samples) row. This is ~5x
    faster on CPU than reductions over the draw axis, which XLA does not fuse into one
    pass when several statistics read the same array.

    **Arguments:**

    - `stats`: the device's statistics so far (leading device axis of size 1).
    - `elongation`: the chunk's elongations.
    - `time`: the chunk's solved sample times, or None (given times: no mean kept).
    - `valid`: which (draw, cable) pairs succeeded (padding draws are not valid).
    - `status`: the chunk's draws per `RESULTS` member and cable.
    - `lo`, `width`: the histogram's lower edge and bin width per (cable, sample).
    - `bins`: the number of equal bins (0: no histogram).

    **Returns:**

    The updated statistics (leading device axis of size 1).
    """
    dtype = stats.mean.dtype
    ncables, nsamples = elongation.shape[1:]
    cells = bins + 2
    col = jnp.arange(ncables * nsamples, dtype=jnp.int32).reshape(ncables, nsamples)
    dropped = ncables * nsamples * cells  # out of bounds: dropped by the scatter

    def body(i, r: Statistics) -> Statistics:
        x = elongation[i].astype(dtype)
        ok = valid[i]
        w = ok[:, None]
        count = r.count + ok.astype(dtype)
        inv = (1.0 / jnp.maximum(count, 1.0))[:, None]
        delta = x - r.mean
        mean = jnp.where(w, r.mean + delta * inv, r.mean)
        m2 = jnp.where(w, r.m2 + delta * (x - mean), r.m2)
        if time is None:
            time_mean = r.time_mean
        else:
            t = time[i].astype(dtype)
            time_mean = jnp.where(w, r.time_mean + (t - r.time_mean) * inv, r.time_mean)
        minimum = jnp.where(w, jnp.minimum(r.minimum, x), r.minimum)
        maximum = jnp.where(w, jnp.maximum(r.maximum, x), r.maximum)
        histogram = r.histogram
        if bins:
            # Bin 0 holds x < lo, bins 1..bins the equal bins of [lo, hi), and
            # bins + 1 holds x >= hi.
            b = jnp.clip(jnp.floor((x - lo) / width), -1, bins).astype(jnp.int32) + 1
            flat = jnp.where(w, col * cells + b, dropped)
            histogram = histogram.at[flat.reshape(-1)].add(1, mode="drop")
        return Statistics(
            count, mean, m2, time_mean, minimum, maximum, r.status, histogram
        )

    init = jax.tree_util.tree_map(lambda a: a[0], stats)
    r = jax.lax.fori_loop(0, elongation.shape[0], body, init)
    r = eqx.tree_at(lambda s: s.status, r, r.status + status)
    return jax.tree_util.tree_map(lambda a: a[None], r)


def merge_devices(stats: Statistics) -> Statistics:
    """Merge the devices' statistics on the host, in float64.

    Means and sums of squared deviations are combined with Chan's pairwise formula;
    extremes, status counts and histograms by min, max and sum.

    **Arguments:**

    - `stats`: the statistics as NumPy arrays with a leading device axis.

    **Returns:**

    One set of statistics, without the device axis.
    """
    count = stats.count[0].astype(float)
    mean = stats.mean[0].astype(float)
    m2 = stats.m2[0].astype(float)
    time_mean = stats.time_mean[0].astype(float)
    for d in range(1, stats.count.shape[0]):
        cd = stats.count[d].astype(float)
        merged = count + cd
        safe = np.maximum(merged, 1.0)[:, None]
        delta = stats.mean[d] - mean
        time_mean = time_mean + (stats.time_mean[d] - time_mean) * (cd[:, None] / safe)
        mean = mean + delta * (cd[:, None] / safe)
        m2 = m2 + stats.m2[d] + delta**2 * (count * cd)[:, None] / safe
        count = merged
    return Statistics(
        count=count,
        mean=mean,
        m2=m2,
        time_mean=time_mean,
        minimum=stats.minimum.min(axis=0).astype(float),
        maximum=stats.maximum.max(axis=0).astype(float),
        status=stats.status.sum(axis=0),
        histogram=stats.histogram.sum(axis=0),
    )


def histogram_edges(
    minimum: np.ndarray, maximum: np.ndarray, bins: int, dtype
) -> tuple[np.ndarray, np.ndarray]:
    """The histogram's bins from the exact range of a first chunk of draws: that range
    widened by half of it on each side, cut into `bins` equal bins.

    **Arguments:**

    - `minimum`, `maximum`: the first chunk's extremes per (cable, sample) (+-inf
        where it has no successful draw).
    - `bins`: the number of equal bins.
    - `dtype`: the simulation's dtype.

    **Returns:**

    The lower edge and the bin width per (cable, sample), in `dtype` (the edges as the
    device sees them).
    """
    lo_raw, hi_raw = minimum.astype(float), maximum.astype(float)
    empty = ~np.isfinite(lo_raw)
    lo_raw, hi_raw = np.where(empty, 0.0, lo_raw), np.where(empty, 0.0, hi_raw)
    pad = (
        0.5 * (hi_raw - lo_raw)
        + 1e-9 * np.maximum(np.abs(lo_raw), np.abs(hi_raw))
        + 1e-12
    )
    lo = (lo_raw - pad).astype(dtype)
    width = ((hi_raw - lo_raw + 2 * pad) / bins).astype(dtype)
    return lo, width


def percentiles_from_draws(
    elongation: np.ndarray, valid: np.ndarray, q: np.ndarray
) -> np.ndarray:
    """Exact percentiles (`numpy.percentile`) of every kept draw, per cable, over the
    successful draws.

    **Arguments:**

    - `elongation`: every draw's elongation, shape `(draws, cables, samples)`.
    - `valid`: which (draw, cable) pairs succeeded, shape `(draws, cables)`.
    - `q`: the percentile levels, in percent.

    **Returns:**

    The percentiles, shape `(q, cables, samples)`; NaN for a cable without a
    successful draw.
    """
    _, ncables, samples = elongation.shape
    values = np.full((q.size, ncables, samples), np.nan)
    for j in range(ncables):
        x = elongation[valid[:, j], j]
        if x.shape[0]:
            values[:, j] = np.percentile(x, q, axis=0)
    return values


def percentiles_from_histogram(
    hist: np.ndarray,
    lo: np.ndarray,
    width: np.ndarray,
    minimum: np.ndarray,
    maximum: np.ndarray,
    count: np.ndarray,
    q: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Percentiles (numpy's linear interpolation between order statistics) from the
    per-(cable, sample) histograms, with a bound on their error.

    **Arguments:**

    - `hist`: the counts, shape `(cables, samples, bins + 2)`: an underflow bin, the
        equal bins, an overflow bin.
    - `lo`, `width`: the lower edge and bin width of the equal bins, per (cable,
        sample).
    - `minimum`, `maximum`: the exact extremes (they bound the under- and overflow
        bins), per (cable, sample).
    - `count`: the number of values, per (cable, sample).
    - `q`: the percentile levels, in percent.

    **Returns:**

    The percentiles and a bound on their absolute error (the width of the bins that
    hold their order statistics), both of shape `(q, cables, samples)`.
    """
    bins = hist.shape[-1] - 2
    cum = np.cumsum(hist, axis=-1, dtype=np.int64)  # values in bins 0..k

    def order_statistic(j):
        # The bin b holding the j-th smallest value (0-based), its edges, and an
        # estimate of the value that spreads the bin's values evenly over the bin.
        b = np.minimum(np.sum(cum <= j[..., None], axis=-1), bins + 1)
        n_b = np.take_along_axis(hist, b[..., None], axis=-1)[..., 0]
        before = np.take_along_axis(cum, b[..., None], axis=-1)[..., 0] - n_b
        left = np.where(b == 0, minimum, lo + (b - 1) * width)
        right = np.where(b == bins + 1, maximum, lo + b * width)
        left, right = np.clip(left, minimum, maximum), np.clip(right, minimum, maximum)
        frac = np.clip((j - before + 0.5) / np.maximum(n_b, 1), 0.0, 1.0)
        est = left + frac * (right - left)
        # The extremes are known exactly.
        first, last = j == 0, j == count - 1
        est = np.where(first, minimum, np.where(last, maximum, est))
        width_b = np.where(first | last, 0.0, right - left)
        return est, width_b

    values, bounds = [], []
    with np.errstate(invalid="ignore"):
        for level in q:
            rank = level / 100.0 * np.maximum(count - 1, 0)
            j0 = np.floor(rank).astype(np.int64)
            j1 = np.minimum(j0 + 1, np.maximum(count - 1, 0))
            frac = rank - j0
            e0, w0 = order_statistic(j0)
            e1, w1 = order_statistic(j1)
            values.append(e0 + frac * (e1 - e0))
            # Each estimate lies in the bin of its order statistic, so the error of
            # the interpolated value is at most the interpolated bin width.
            bounds.append((1 - frac) * w0 + frac * w1)
    return np.stack(values), np.stack(bounds)
