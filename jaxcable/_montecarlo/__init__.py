from .montecarlo import (
    IndependentParameters as IndependentParameters,
    LogNormal as LogNormal,
)
