"""Monte-Carlo of cable sets: parameter distributions and samplers, time-stamped force
histories, and `monte_carlo` (draws x cables x loads, chunked and sharded over devices,
reduced to percentiles of elongation over time)."""

from .distributions import (
    AbstractDistribution as AbstractDistribution,
    LogNormal as LogNormal,
    Normal as Normal,
    Uniform as Uniform,
)
from .inputs import ForceHistory as ForceHistory
from .method import MonteCarlo as MonteCarlo
from .montecarlo import MonteCarloResult as MonteCarloResult, monte_carlo as monte_carlo
from .samplers import (
    AbstractParameterSampler as AbstractParameterSampler,
    CorrelatedParameters as CorrelatedParameters,
    IndependentParameters as IndependentParameters,
)
