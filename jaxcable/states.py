"""The scan carries, for authors of their own time loops and controllers.

The public API takes and returns these states ([`jaxcable.init_state`][],
[`jaxcable.step`][], [`jaxcable.controller_init`][], [`jaxcable.controller_step`][]);
a user passes them on without looking inside. They are here, not at the top level,
for code that reads or builds them: `CableState` (one cable driven sample by sample),
`ControllerState` (a set of cables in a controller) and each model's own state.
"""

from ._drive import CableState as CableState, ControllerState as ControllerState
from ._models import (
    BeddingInState as BeddingInState,
    BoucWenState as BoucWenState,
    BurgersState as BurgersState,
    CovariateStrainState as CovariateStrainState,
    DiscoveredTermState as DiscoveredTermState,
    FiveElementState as FiveElementState,
    HereditaryState as HereditaryState,
    HookeState as HookeState,
    IntegratedState as IntegratedState,
    MechanoSorptiveState as MechanoSorptiveState,
    SecondRetardationState as SecondRetardationState,
    SensorDriftState as SensorDriftState,
    StressNonlinearCreepState as StressNonlinearCreepState,
)
