import importlib.metadata

from ._abstract import (
    AbstractCableModel as AbstractCableModel,
    StrainParts as StrainParts,
)
from ._baselines import (
    BoucWenModel as BoucWenModel,
    BoucWenState as BoucWenState,
    BurgersModel as BurgersModel,
    BurgersState as BurgersState,
    HookeModel as HookeModel,
    HookeState as HookeState,
)
from ._cable import Cable as Cable
from ._five_element import (
    FiveElementModel as FiveElementModel,
    FiveElementState as FiveElementState,
)
from ._integrated import (
    IntegratedModel as IntegratedModel,
    IntegratedState as IntegratedState,
)
from ._io import TestData as TestData, read_csv as read_csv, write_csv as write_csv
from ._newton import Newton as Newton
from ._protocol import Protocol as Protocol
from ._results import RESULTS as RESULTS
from ._simulate import (
    CableState as CableState,
    Trajectory as Trajectory,
    init_state as init_state,
    simulate_elongation_history as simulate_elongation_history,
    simulate_force_history as simulate_force_history,
    simulate_rate_test as simulate_rate_test,
    step as step,
)
from ._surface import (
    PIAO_TABLE3 as PIAO_TABLE3,
    ParameterSurface as ParameterSurface,
    piao_five_element as piao_five_element,
)


__version__ = importlib.metadata.version("jaxcable")
