"""Model extensions: physical effects a base model lacks, each a wrapper around any
[`jaxcable.AbstractCableModel`][] (an [`AbstractExtension`][]: wrap, don't subclass),
composable by nesting, e.g. `SensorDrift(BeddingIn(IntegratedModel()))`.

By family: `creep.py` (the base's creep changed), `temperature.py` (the base on
reduced time), `apparatus.py` (what the test set-up adds) and `covariate.py` (what a
recorded covariate drives). [`EXTENSIONS`][] lists
the candidates of the diagnosis.

At the null value of its effect parameter (`beta = 0`, `weight = 0`, `E_k = inf`, `n = 0`,
`activation_energy = 0`, `c1 = 0`, `compliance = 0`, `s_b = 0`, `drift_rate = 0`)
every extension reproduces its base model exactly.

Every extension is continuous in the force history: none switches on the sign of a
force change, on a threshold of the force or through a division guard that jumps, so
a perturbation d of every force sample moves its own contribution by at most a stated
multiple of d, which does not grow with the total variation of the noise (each
docstring says how). Measured forces are noisy, and a state that switched on such a
sign would jump with every noise blip.
"""

from ..base import AbstractExtension
from . import memory as memory
from .apparatus import (
    BeddingIn as BeddingIn,
    BeddingInState as BeddingInState,
    SensorDrift as SensorDrift,
    SensorDriftState as SensorDriftState,
    TerminationCompliance as TerminationCompliance,
)
from .covariate import (
    CovariateShift as CovariateShift,
    CovariateStrain as CovariateStrain,
    CovariateStrainState as CovariateStrainState,
    MechanoSorptive as MechanoSorptive,
    MechanoSorptiveState as MechanoSorptiveState,
)
from .creep import (
    Hardening as Hardening,
    HardeningState as HardeningState,
    Hereditary as Hereditary,
    HereditaryState as HereditaryState,
    SecondRetardation as SecondRetardation,
    SecondRetardationState as SecondRetardationState,
    StressNonlinearCreep as StressNonlinearCreep,
    StressNonlinearCreepState as StressNonlinearCreepState,
)
from .discovered import (
    TERMS as TERMS,
    DiscoveredTerm as DiscoveredTerm,
    DiscoveredTermState as DiscoveredTermState,
)
from .temperature import (
    AbstractTemperatureShift as AbstractTemperatureShift,
    TemperatureShift as TemperatureShift,
    TemperatureShiftWLF as TemperatureShiftWLF,
    log_shift_arrhenius as log_shift_arrhenius,
    log_shift_wlf as log_shift_wlf,
    with_data_reference as with_data_reference,
)


EXTENSIONS: dict[str, type[AbstractExtension]] = {
    cls.EXTENSION_ID: cls
    for cls in (
        Hardening,
        Hereditary,
        SecondRetardation,
        StressNonlinearCreep,
        TemperatureShift,
        TerminationCompliance,
        BeddingIn,
        SensorDrift,
    )
}
"""The candidate extensions of the diagnosis, id -> class, in a fixed order: creep
changes first (Park's hardening of the instantaneous strain innermost), then
temperature, then the apparatus. ([`DiscoveredTerm`][], id
`discovered`, is not a catalogue candidate: the discovery builds its terms.)"""

COVARIATE_EXTENSIONS: dict[str, type[AbstractExtension]] = {
    cls.EXTENSION_ID: cls for cls in (CovariateStrain, MechanoSorptive, CovariateShift)
}
"""The extensions driven by a recorded covariate (`Cable.covariate`, set from a
column by `jaxcable.fit(..., covariate=NAME)`), id -> class: a strain proportional to
it, creep driven by its changes under stress, a time shift by it. Not in
[`EXTENSIONS`][]: the catalogue's candidates run on data without a covariate."""
