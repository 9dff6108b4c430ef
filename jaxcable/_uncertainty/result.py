"""The outcome of [`jaxcable.sample_posterior`][]: `Posterior`, its summary and its
conversions (ArviZ, [`jaxcable.CorrelatedParameters`][], PARAMS.json)."""

import dataclasses

import equinox as eqx
import numpy as np

from .._fit import FitResult, field_at
from .._json import jsonable
from .._models import AbstractCableModel
from .._montecarlo import CorrelatedParameters


QUANTILES = (0.025, 0.5, 0.975)


@dataclasses.dataclass(frozen=True, eq=False)
class Posterior:
    """Draws from the posterior of a model's fitted parameters.

    **Fields:**

    - `model`: the least-squares fitted model the chains started from.
    - `names`: the sampled parameters.
    - `units`: their SI units.
    - `samples`: the draws, natural values (SI), `(chains, draws, parameters)`.
    - `unconstrained`: the same draws on the fit's unconstrained scale u.
    - `transforms`: each parameter's reparameterisation (see [`jaxcable.fit`][]).
    - `rhat`: rank-normalised split R-hat of each parameter (<= 1.01: converged).
    - `ess`: bulk effective sample size of each parameter.
    - `divergences`: divergent transitions while sampling (0 expected).
    - `acceptance`: mean acceptance of the sampling phase.
    - `step_size`: the adapted step size (in units of the metric).
    - `mean_steps`: integration steps (gradients) per draw, mean.
    - `noise`: the noise model, `"fitted"` or `"robust"`.
    - `noise_sd`: with `"robust"`, each test's noise standard deviation in its
        residual unit; None with `"fitted"`.
    - `fit`: the least-squares [`jaxcable.FitResult`][] it started from.
    - `seconds`: wall time of the sampling, fit and compilation included, s.
    """

    model: AbstractCableModel
    names: tuple[str, ...]
    units: tuple[str, ...]
    samples: np.ndarray
    unconstrained: np.ndarray
    transforms: tuple[str, ...]
    rhat: np.ndarray
    ess: np.ndarray
    divergences: int
    acceptance: float
    step_size: float
    mean_steps: float
    noise: str
    noise_sd: np.ndarray | None
    fit: FitResult
    seconds: float

    @property
    def flat(self) -> np.ndarray:
        """Every chain's draws together, `(chains * draws, parameters)`."""
        return self.samples.reshape(-1, self.samples.shape[-1])

    @property
    def mean(self) -> np.ndarray:
        """The posterior mean of each parameter, SI."""
        return self.flat.mean(axis=0)

    @property
    def sd(self) -> np.ndarray:
        """The posterior standard deviation of each parameter, SI."""
        return self.flat.std(axis=0, ddof=1)

    def quantiles(self, q) -> np.ndarray:
        """Posterior quantiles: `(len(q), parameters)` for a sequence `q` of
        probabilities in [0, 1]."""
        return np.quantile(self.flat, np.asarray(q, float), axis=0)

    def interval(self, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """The central credible interval of each parameter, `(low, high)`.

        **Arguments:**

        - `level`: its probability, in (0, 1).
        """
        if not 0 < level < 1:
            raise ValueError(f"`level` must be in (0, 1), got {level!r}.")
        low, high = self.quantiles([(1 - level) / 2, (1 + level) / 2])
        return low, high

    @property
    def converged(self) -> bool:
        """Whether every parameter has R-hat <= 1.01 and no draw diverged."""
        return bool(np.all(self.rhat <= 1.01)) and self.divergences == 0

    def rows(self) -> list[dict]:
        """The summary, one dict per parameter: `name`, `unit`, `mean`, `sd`,
        `q2.5`, `q50`, `q97.5`, `rhat`, `ess` (SI; non-finite as None)."""
        q = self.quantiles(QUANTILES)
        out = []
        for i, (name, unit) in enumerate(zip(self.names, self.units)):
            out.append(
                {
                    "name": name,
                    "unit": unit,
                    "mean": jsonable(float(self.mean[i])),
                    "sd": jsonable(float(self.sd[i])),
                    "q2.5": jsonable(float(q[0, i])),
                    "q50": jsonable(float(q[1, i])),
                    "q97.5": jsonable(float(q[2, i])),
                    "rhat": jsonable(float(self.rhat[i])),
                    "ess": jsonable(float(self.ess[i])),
                }
            )
        return out

    def to_dict(self) -> dict:
        """The summary as PARAMS.json's `posterior` entry: the sampler's settings and
        outcome and `rows()` under `parameters`."""
        chains, draws = self.samples.shape[:2]
        return {
            "method": "NUTS (BlackJAX), warm-started from the least-squares fit",
            "noise": self.noise,
            "chains": int(chains),
            "draws_per_chain": int(draws),
            "divergences": int(self.divergences),
            "acceptance": float(self.acceptance),
            "step_size": float(self.step_size),
            "mean_steps": float(self.mean_steps),
            "converged": self.converged,
            "parameters": self.rows(),
        }

    def summary(self) -> str:
        """A text table: mean, sd, 2.5 / 50 / 97.5 % quantiles, R-hat and ESS of
        each parameter, with the sampler's outcome above it."""
        chains, draws = self.samples.shape[:2]
        lines = [
            f"posterior: {chains} chain(s) x {draws} draws, NUTS, noise {self.noise}; "
            f"{self.divergences} divergence(s), acceptance {self.acceptance:.2f}, "
            f"{self.mean_steps:.1f} steps per draw",
            f"{'parameter':<12} {'mean':>11} {'sd':>10} {'2.5%':>11} {'50%':>11} "
            f"{'97.5%':>11} {'R-hat':>6} {'ESS':>6}  unit",
        ]
        for r in self.rows():
            cells = [r[k] if r[k] is not None else float("nan") for k in r][2:]
            mean, sd, lo, mid, hi, rhat, ess = cells
            lines.append(
                f"{r['name'][:12]:<12} {mean:>11.5g} {sd:>10.3g} {lo:>11.5g} "
                f"{mid:>11.5g} {hi:>11.5g} {rhat:>6.3f} {ess:>6.0f}  {r['unit']}"
            )
        if not self.converged:
            # Unmixed chains' quantiles are not the posterior's: say so beside them.
            unmixed = [n for n, r in zip(self.names, self.rhat) if not r <= 1.01]
            lines.append(
                "NOT CONVERGED: "
                + (f"R-hat > 1.01 for {', '.join(unmixed)}" if unmixed else "")
                + ("; " if unmixed and self.divergences else "")
                + (f"{self.divergences} divergent draws" if self.divergences else "")
                + ". Run longer chains; divergences with a low ESS often mean a "
                "parameter the data leave flat on one side of a kink (e.g. E1r below "
                "about E1c in Park's Eq. 9)."
            )
        return "\n".join(lines)

    def to_arviz(self):
        """The draws as ArviZ's data structure (an `xarray.DataTree` with ArviZ >= 1,
        an `InferenceData` before), for ArviZ's diagnostics and plots.

        **Returns:**

        The converted draws: group `posterior`, one variable per parameter (dims
        `chain`, `draw`; a dotted name such as `base.E1` kept as it is).

        **Raises:**

        `ImportError` when neither `arviz_base` nor `arviz` is installed.
        """
        variables = {n: self.samples[:, :, i] for i, n in enumerate(self.names)}
        try:
            import arviz_base  # pyright: ignore[reportMissingImports]

            return arviz_base.from_dict({"posterior": variables})
        except ImportError:
            pass
        try:
            import arviz  # pyright: ignore[reportMissingImports]
        except ImportError:
            raise ImportError(
                "Posterior.to_arviz needs ArviZ: pip install arviz (or arviz-base)."
            ) from None
        return arviz.from_dict(posterior=variables)

    def median_model(self) -> AbstractCableModel:
        """The fitted model with every sampled parameter at its posterior median."""
        median = np.median(self.flat, axis=0)
        model = self.model
        return eqx.tree_at(
            lambda m: [field_at(m, n) for n in self.names],
            model,
            [
                np.asarray(v, np.asarray(field_at(model, n)).dtype)
                for n, v in zip(self.names, median)
            ],
        )

    def correlated_parameters(self) -> CorrelatedParameters:
        """A [`jaxcable.CorrelatedParameters`][] matching the posterior, for
        [`jaxcable.monte_carlo`][].

        Positive parameters are drawn log-normally around their posterior median
        with the covariance of the log draws (others normally, with the draws'
        covariance), so the Monte-Carlo's draws reproduce the posterior's first two
        moments on the scale the posterior is closest to normal on.

        **Returns:**

        The sampler, its model `median_model()`.
        """
        flat = self.flat
        positive = np.all(flat > 0, axis=0)
        median = np.median(flat, axis=0)
        z = np.where(positive, np.log(np.where(positive, flat, 1.0)), flat)
        cov_z = np.atleast_2d(np.cov(z, rowvar=False))
        # CorrelatedParameters draws mean_i exp(z_i) with z ~ N(0, C_ij / (s_i s_j)).
        s = np.where(positive, median, 1.0)
        covariance = cov_z * np.outer(s, s)
        log_space = [n for n, q in zip(self.names, positive) if q]
        return CorrelatedParameters(
            self.median_model(), self.names, covariance, log_space=log_space
        )
