from .fit import (
    FitResult as FitResult,
    IdentifiabilityWarning as IdentifiabilityWarning,
    as_test_list as as_test_list,
    fit as fit,
    pad_tests as pad_tests,
    residuals as residuals,
    test_id as test_id,
)
