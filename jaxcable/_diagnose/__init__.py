from .diagnose import diagnose as diagnose
from .elongations import model_elongations as model_elongations
from .heldout import (
    heldout_rmse as heldout_rmse,
    heldout_start as heldout_start,
    noise_level as noise_level,
)
from .result import (
    MAX_DELTA_BIC as MAX_DELTA_BIC,
    MIN_EXCESS as MIN_EXCESS,
    MIN_GAIN_PCT as MIN_GAIN_PCT,
    MIN_SIZE_Z as MIN_SIZE_Z,
    Candidate as Candidate,
    Diagnosis as Diagnosis,
)
from .structure import residual_structure as residual_structure
