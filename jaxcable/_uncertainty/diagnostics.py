"""Convergence diagnostics of Markov chains: the rank-normalised split R-hat and the
bulk effective sample size of Vehtari, Gelman, Simpson, Carpenter & Buerkner (2021),
"Rank-normalization, folding, and localization: an improved R-hat", Bayesian Analysis
16(2), the estimators Stan and ArviZ report. Host-side, numpy, float64.
"""

import math

import numpy as np


def _normal_ppf(p: np.ndarray) -> np.ndarray:
    """The standard normal quantile function (Acklam's rational approximation refined
    by one Halley step: accurate to ~1e-15)."""
    a = [-39.69683028665376, 220.9460984245205, -275.9285104469687]
    a += [138.3577518672690, -30.66479806614716, 2.506628277459239]
    b = [-54.47609879822406, 161.5858368580409, -155.6989798598866]
    b += [66.80131188771972, -13.28068155288572]
    c = [-0.007784894002430293, -0.3223964580411365, -2.400758277161838]
    c += [-2.549732539343734, 4.374664141464968, 2.938163982698783]
    d = [0.007784695709041462, 0.3224671290700398, 2.445134137142996]
    d += [3.754408661907416]
    p = np.asarray(p, float)
    low = np.minimum(p, 1.0 - p)
    q = np.sqrt(-2.0 * np.log(low))
    tail = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / (
        (((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0
    )
    tail = np.where(p < 0.5, tail, -tail)
    r = (p - 0.5) ** 2
    mid = (
        (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5])
        * (p - 0.5)
        / (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0)
    )
    x = np.where(low < 0.02425, tail, mid)
    # One Halley step on the normal CDF.
    erfc = np.vectorize(math.erfc)
    e = 0.5 * erfc(-x / math.sqrt(2.0)) - p
    u = e * math.sqrt(2.0 * math.pi) * np.exp(0.5 * x * x)
    return x - u / (1.0 + 0.5 * x * u)


def _split(x: np.ndarray) -> np.ndarray:
    """`(chains, draws)` -> `(2 chains, draws // 2)`: each chain's halves (an odd
    middle draw dropped)."""
    half = x.shape[1] // 2
    return np.concatenate([x[:, :half], x[:, x.shape[1] - half :]], axis=0)


def _rank_normalise(x: np.ndarray) -> np.ndarray:
    """The draws replaced by the normal scores of their pooled ranks (average ranks
    for ties), fractional offset 3/8 as in Vehtari et al."""
    flat = x.ravel()
    order = np.argsort(flat, kind="mergesort")
    ranks = np.empty(flat.size)
    ranks[order] = np.arange(1, flat.size + 1)
    # Ties (a chain that did not move) share their average rank.
    values, inverse = np.unique(flat, return_inverse=True)
    if values.size < flat.size:
        sums = np.bincount(inverse, weights=ranks)
        counts = np.bincount(inverse)
        ranks = (sums / counts)[inverse]
    return _normal_ppf((ranks - 0.375) / (flat.size + 0.25)).reshape(x.shape)


def _rhat(x: np.ndarray) -> float:
    """Gelman-Rubin R-hat of `(chains, draws)`, chains as given."""
    m, n = x.shape
    between = n * np.var(x.mean(axis=1), ddof=1)
    within = np.mean(np.var(x, axis=1, ddof=1))
    if within <= 0:
        return math.inf if between > 0 else math.nan
    return float(math.sqrt(((n - 1) / n * within + between / n) / within))


def split_rhat(draws: np.ndarray) -> float:
    """Rank-normalised split R-hat of one parameter's draws.

    **Arguments:**

    - `draws`: `(chains, draws)`, at least 4 draws per chain.

    **Returns:**

    R-hat (1 at convergence; the usual threshold is 1.01); NaN for draws that do not
    vary at all.
    """
    x = _split(np.asarray(draws, float))
    return _rhat(_rank_normalise(x))


def _ess(x: np.ndarray) -> float:
    """Multi-chain effective sample size of `(chains, draws)` (Geyer's initial
    monotone sequence on the averaged autocorrelation, as in Stan)."""
    m, n = x.shape
    if n < 4:
        return math.nan
    centred = x - x.mean(axis=1, keepdims=True)
    size = 1 << (2 * n - 1).bit_length()
    spectrum = np.fft.rfft(centred, n=size, axis=1)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), n=size, axis=1)[:, :n] / n
    chain_var = acov[:, 0] * n / (n - 1)
    within = chain_var.mean()
    var_plus = within * (n - 1) / n
    if m > 1:
        var_plus += np.var(x.mean(axis=1), ddof=1)
    if not var_plus > 0:
        return math.nan
    rho = 1.0 - (within - acov.mean(axis=0)) / var_plus
    rho[0] = 1.0
    # Sums of adjacent pairs, kept while positive and made monotone.
    total, previous, t = 0.0, math.inf, 0
    while t + 1 < n:
        pair = rho[t] + rho[t + 1]
        if pair < 0:
            break
        pair = min(pair, previous)
        total += pair
        previous = pair
        t += 2
    tau = -1.0 + 2.0 * total
    tau = max(tau, 1.0 / math.log10(m * n))
    return float(m * n / tau)


def bulk_ess(draws: np.ndarray) -> float:
    """Bulk effective sample size of one parameter's draws (rank-normalised split
    chains).

    **Arguments:**

    - `draws`: `(chains, draws)`.

    **Returns:**

    The effective number of independent draws (NaN for draws that do not vary).
    """
    return _ess(_rank_normalise(_split(np.asarray(draws, float))))
