import importlib.metadata

from ._abstract import AbstractCableModel as AbstractCableModel, StrainParts as StrainParts
from ._cable import Cable as Cable
from ._integrated import (
    IntegratedModel as IntegratedModel,
    IntegratedState as IntegratedState,
)
from ._newton import Newton as Newton
from ._protocol import Protocol as Protocol
from ._results import RESULTS as RESULTS
from ._simulate import (
    CableState as CableState,
    init_state as init_state,
    simulate_elongation_history as simulate_elongation_history,
    simulate_force_history as simulate_force_history,
    simulate_rate_test as simulate_rate_test,
    step as step,
    Trajectory as Trajectory,
)


__version__ = importlib.metadata.version("jaxcable")
