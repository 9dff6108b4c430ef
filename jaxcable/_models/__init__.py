from .base import (
    AbstractCableModel as AbstractCableModel,
    StrainParts as StrainParts,
)
from .baselines import (
    BoucWenModel as BoucWenModel,
    BurgersModel as BurgersModel,
    HookeModel as HookeModel,
)
from .extensions import (
    EXTENSIONS as EXTENSIONS,
    TerminationCompliance as TerminationCompliance,
)
from .park import (
    IntegratedModel as IntegratedModel,
)
from .piao import (
    FiveElementModel as FiveElementModel,
    FiveElementState as FiveElementState,
)
from .piao_surface import (
    PIAO_TABLE1 as PIAO_TABLE1,
    PIAO_TABLE3 as PIAO_TABLE3,
    ParameterSurface as ParameterSurface,
)
from .registry import (
    BY_CLI_NAME as BY_CLI_NAME,
    CLASSES_BY_NAME as CLASSES_BY_NAME,
    DEFAULT_CLI_MODEL as DEFAULT_CLI_MODEL,
    MODELS as MODELS,
    PARK_IDENTIFIABLE as PARK_IDENTIFIABLE,
    ParameterInfo as ParameterInfo,
    cli_name as cli_name,
    identifiable as identifiable,
    parameter_info as parameter_info,
)
