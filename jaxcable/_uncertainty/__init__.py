from .budget import TestBudget as TestBudget
from .designed import DesignedTest as DesignedTest, design_test as design_test
from .diagnostics import bulk_ess as bulk_ess, split_rhat as split_rhat
from .discriminate import (
    DiscriminatingTest as DiscriminatingTest,
    design_discriminating_test as design_discriminating_test,
)
from .methods import NUTS as NUTS, TestDesign as TestDesign
from .posterior import sample_posterior as sample_posterior
from .priors import PRIOR_SCALE as PRIOR_SCALE
from .result import Posterior as Posterior
