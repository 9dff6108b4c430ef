from .base import BaseFit as BaseFit, stack_of as stack_of
from .diagnose import diagnose as diagnose
from .diagnosis import Candidate as Candidate, Diagnosis as Diagnosis
from .discover import DiscoveryResult as DiscoveryResult, discover as discover
from .family import FAMILY_EXCESS as FAMILY_EXCESS
from .library import (
    damage_integral as damage_integral,
    memory_library as memory_library,
    step_inputs as step_inputs,
)
from .methods import (
    CandidateSearch as CandidateSearch,
    Discovery as Discovery,
    HeldOut as HeldOut,
    heldout_start as heldout_start,
    time_split as time_split,
)
from .noise import (
    channel_noise as channel_noise,
    grid_step as grid_step,
    white_part as white_part,
)
from .plan import Plan as Plan, covariate_columns as covariate_columns
from .rule import (
    MAX_DELTA_BIC as MAX_DELTA_BIC,
    MAX_DIVERGENCE as MAX_DIVERGENCE,
    MAX_FLOOR_RATIO as MAX_FLOOR_RATIO,
    MIN_AUTOCORRELATION as MIN_AUTOCORRELATION,
    MIN_EXCESS as MIN_EXCESS,
    MIN_EXPLAINED_PCT as MIN_EXPLAINED_PCT,
    MIN_GAIN_PCT as MIN_GAIN_PCT,
    MIN_SIZE_Z as MIN_SIZE_Z,
    Verdict as Verdict,
    decide as decide,
    diverges as diverges,
    explained_pct as explained_pct,
    explained_rmse_pct as explained_rmse_pct,
)
from .scoring import (
    Scoring as Scoring,
    bic as bic,
    heldout_rmse as heldout_rmse,
    model_elongations as model_elongations,
    model_outputs as model_outputs,
    noise_floor as noise_floor,
    noise_level as noise_level,
    scored_residuals as scored_residuals,
    scoring as scoring,
)
from .structure import (
    rate_of_change as rate_of_change,
    residual_structure as residual_structure,
    test_covariates as test_covariates,
)
