"""The cable models: the interface ([`AbstractCableModel`][], [`StrainParts`][]), Park's
integrated model, Piao's five-element model and its parameter surfaces, the baselines,
the extensions that wrap any of them ([`AbstractExtension`][]) and the one registry."""

from .base import (
    AbstractCableModel as AbstractCableModel,
    AbstractExtension as AbstractExtension,
    StrainParts as StrainParts,
)
from .baselines import (
    BoucWenModel as BoucWenModel,
    BoucWenState as BoucWenState,
    BurgersModel as BurgersModel,
    BurgersState as BurgersState,
    HookeModel as HookeModel,
    HookeState as HookeState,
)
from .extensions import (
    COVARIATE_EXTENSIONS as COVARIATE_EXTENSIONS,
    EXTENSIONS as EXTENSIONS,
    AbstractTemperatureShift as AbstractTemperatureShift,
    BeddingIn as BeddingIn,
    BeddingInState as BeddingInState,
    CovariateShift as CovariateShift,
    CovariateStrain as CovariateStrain,
    CovariateStrainState as CovariateStrainState,
    DiscoveredTerm as DiscoveredTerm,
    DiscoveredTermState as DiscoveredTermState,
    Hardening as Hardening,
    HardeningState as HardeningState,
    Hereditary as Hereditary,
    HereditaryState as HereditaryState,
    MechanoSorptive as MechanoSorptive,
    MechanoSorptiveState as MechanoSorptiveState,
    SecondRetardation as SecondRetardation,
    SecondRetardationState as SecondRetardationState,
    SensorDrift as SensorDrift,
    SensorDriftState as SensorDriftState,
    StressNonlinearCreep as StressNonlinearCreep,
    StressNonlinearCreepState as StressNonlinearCreepState,
    TemperatureShift as TemperatureShift,
    TemperatureShiftWLF as TemperatureShiftWLF,
    TerminationCompliance as TerminationCompliance,
    discovered as discovered,
    log_shift_arrhenius as log_shift_arrhenius,
    log_shift_wlf as log_shift_wlf,
    memory as memory,
    with_data_reference as with_data_reference,
)
from .fields import (
    field_facts as field_facts,
    parameter as parameter,
    parameter_table as parameter_table,
    setting as setting,
    transform_table as transform_table,
)
from .findley import (
    FindleyModel as FindleyModel,
    FindleyState as FindleyState,
)
from .park import (
    IntegratedModel as IntegratedModel,
    IntegratedState as IntegratedState,
)
from .piao import (
    PIAO_TABLE1 as PIAO_TABLE1,
    AbstractFiveElement as AbstractFiveElement,
    FiveElementModel as FiveElementModel,
    FiveElementState as FiveElementState,
    table1_field as table1_field,
)
from .piao_surface import (
    PIAO_TABLE3 as PIAO_TABLE3,
    ParameterSurface as ParameterSurface,
    piao_five_element as piao_five_element,
)
from .registry import (
    BY_CLI_NAME as BY_CLI_NAME,
    CLASSES_BY_NAME as CLASSES_BY_NAME,
    DEFAULT_CLI_MODEL as DEFAULT_CLI_MODEL,
    MODELS as MODELS,
    PARK_IDENTIFIABLE as PARK_IDENTIFIABLE,
    ParameterInfo as ParameterInfo,
    cli_name as cli_name,
    describe as describe,
    identifiable as identifiable,
    innermost as innermost,
    parameter_info as parameter_info,
)
