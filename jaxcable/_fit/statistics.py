"""The uncertainty of a fit: covariance, standard errors, correlations and the
identifiability warnings, host-side in float64 from J^T J at the optimum.
"""

import dataclasses
import math
from collections.abc import Sequence

import numpy as np


class IdentifiabilityWarning(UserWarning):
    """Issued by [`jaxcable.fit`][] for parameters the data cannot identify."""


# Identifiability thresholds (see `jaxcable.fit`).
_MAX_RELATIVE_ERROR = 1.0
_MAX_CORRELATION = 0.99
_MIN_SINGULAR_RATIO = 1e-6
# Relative rounding level of the eigenvalues of J^T J (float64).
_ROUNDING = 1e-13


@dataclasses.dataclass(frozen=True)
class Statistics:
    """The fitted parameters' values and uncertainty.

    **Fields:**

    - `values`: the natural values, SI.
    - `covariance`: their covariance.
    - `correlation`: `covariance` normalised by `stderr`.
    - `stderr`: their standard errors.
    - `singular_values`: of J (in u), largest first.
    - `warnings`: the identifiability warnings.
    """

    values: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    stderr: np.ndarray
    singular_values: np.ndarray
    warnings: tuple[str, ...]

    @classmethod
    def undefined(cls, p: int) -> "Statistics":
        """NaN everywhere and no warning: the statistics of a fit that failed."""
        return cls(
            values=np.full(p, np.nan),
            covariance=np.full((p, p), np.nan),
            correlation=np.full((p, p), np.nan),
            stderr=np.full(p, np.nan),
            singular_values=np.full(p, np.nan),
            warnings=(),
        )


def _identifiability(
    labels: Sequence[str],
    values: np.ndarray,
    stderr: np.ndarray,
    correlation: np.ndarray,
    s: np.ndarray,
    vt: np.ndarray,
) -> list[str]:
    """The warnings of the three rules documented in [`jaxcable.fit`][].

    **Arguments:**

    - `labels`, `values`, `stderr`, `correlation`: the fitted parameters'.
    - `s`, `vt`: the singular values of J (largest first) and its right singular
        vectors (rows).

    **Returns:**

    One message per finding.
    """
    out = []
    for i, name in enumerate(labels):
        rel = stderr[i] / abs(values[i]) if values[i] != 0 else math.inf
        if not rel <= _MAX_RELATIVE_ERROR:
            out.append(
                f"{name}: relative standard error {100 * rel:.3g} % > "
                f"{100 * _MAX_RELATIVE_ERROR:g} %; the data do not determine it."
            )
    p = len(labels)
    for i in range(p):
        for j in range(i + 1, p):
            c = correlation[i, j]
            if abs(c) > _MAX_CORRELATION:
                out.append(
                    f"{labels[i]} and {labels[j]}: correlation {c:+.4f} (|r| > "
                    f"{_MAX_CORRELATION}); the data determine only a combination."
                )
    if s.size and s[0] > 0:
        for k in np.flatnonzero(s < _MIN_SINGULAR_RATIO * s[0]):
            weights = np.abs(vt[int(k)])
            involved = [labels[int(i)] for i in np.flatnonzero(weights > 0.3)]
            out.append(
                f"{', '.join(involved)}: near-zero singular value of the Jacobian "
                f"({s[k] / s[0]:.2g} of the largest); the residuals do not change "
                "along this combination."
            )
    return out


def _covariance(
    gram: np.ndarray, g: np.ndarray, sigma2: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`(covariance, stderr, correlation)` of the natural parameters: sigma^2
    (J^T J)^-1 in u, inverted after scaling J's columns to unit norm, carried to the
    natural parameters by the delta method, G C G^T with G = `g` = dx/du."""
    norms = np.sqrt(np.clip(np.diag(gram), 0.0, None))
    d = np.where(norms > 0, norms, 1.0)
    w, v = np.linalg.eigh(gram / np.outer(d, d))
    # Eigenvalues below rounding level are raised to it: a direction the data do not
    # determine then shows as a huge variance and a correlation of +-1 between the
    # parameters that share it, which names them (a pseudo-inverse would drop it).
    w = np.maximum(w, _ROUNDING * max(w[-1], 0.0))
    cov_u = sigma2 * ((v / np.where(w > 0, w, np.inf)) @ v.T) / np.outer(d, d)
    cov = g @ cov_u @ g.T
    stderr = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    # A parameter the residuals do not depend on at all has an unbounded variance.
    singular = norms == 0
    stderr = np.where(singular, np.inf, stderr)
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(stderr, stderr)
    # No correlation is defined for a parameter of unbounded variance.
    corr = np.where(np.isfinite(corr), corr, np.nan)
    corr[singular, :] = np.nan
    corr[:, singular] = np.nan
    np.fill_diagonal(corr, 1.0)
    return cov, stderr, corr


def statistics(
    gram, natural_jacobian, natural, ssr: float, n: int, labels: Sequence[str]
) -> Statistics:
    """Host-side (float64) covariance, standard errors, correlation and
    identifiability warnings at the chosen optimum (see [`jaxcable.fit`][]).

    Works on the p x p matrix J^T J, formed in the kernel, not on the tall J: LAPACK
    on a tall matrix through a multi-threaded OpenBLAS on a loaded machine can cost
    more than the whole fit (its threads spin). The singular values of J for
    the third rule are the square roots of J^T J's eigenvalues (resolved down to ~1e-8
    of the largest in float64, well below the rule's 1e-6).

    **Arguments:**

    - `gram`: J^T J, J the Jacobian of the residuals (m) in u.
    - `natural_jacobian`: dx/du.
    - `natural`: the natural values x.
    - `ssr`: the sum of squared residuals, m^2.
    - `n`: the number of fitted samples.
    - `labels`: the fitted parameters' labels (p of them).

    **Returns:**

    The `Statistics`, with sigma^2 = SSR / (n - p).
    """
    gram = np.asarray(gram, float)
    values = np.asarray(natural, float)
    sigma2 = ssr / (n - len(labels))
    cov, stderr, corr = _covariance(gram, np.asarray(natural_jacobian, float), sigma2)
    # Singular values of J (largest first) and its right singular vectors (rows).
    w_raw, v_raw = np.linalg.eigh(gram)
    s = np.sqrt(np.clip(w_raw[::-1], 0.0, None))
    vt = v_raw[:, ::-1].T
    messages = _identifiability(labels, values, stderr, corr, s, vt)
    return Statistics(values, cov, corr, stderr, s, tuple(messages))
