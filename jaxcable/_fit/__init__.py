from .data import (
    PaddedTests as PaddedTests,
    as_test_list as as_test_list,
    pad_tests as pad_tests,
    resolve_drives as resolve_drives,
    test_id as test_id,
)
from .each import fit_each as fit_each
from .exported import cached_fit_kernels as cached_fit_kernels
from .fit import fit as fit
from .loss import make_loss as make_loss
from .parameters import declared_parameters as declared_parameters, field_at as field_at
from .problem import (
    make_problem as make_problem,
    residuals as residuals,
)
from .responses import model_responses as model_responses, responses as responses
from .result import FitResult as FitResult
from .shared import fit_subset as fit_subset, shared_layout as shared_layout
from .solver import (
    LevenbergMarquardt as LevenbergMarquardt,
    residuals_and_jacobian as residuals_and_jacobian,
    with_jacobian_jvp as with_jacobian_jvp,
)
from .start import (
    StartMovedWarning as StartMovedWarning,
    StartScaling as StartScaling,
    retardation_times as retardation_times,
    scaled_start as scaled_start,
    start_failure as start_failure,
    start_scaling as start_scaling,
)
from .statistics import IdentifiabilityWarning as IdentifiabilityWarning
