from .calibration import (
    SK78_START as SK78_START,
    Calibration as Calibration,
    calibrate_sk78 as calibrate_sk78,
)
from .combined_effects import (
    HIDDEN_PAIRS as HIDDEN_PAIRS,
    hidden_pair_dataset as hidden_pair_dataset,
    hidden_pair_model as hidden_pair_model,
    pair_sizes as pair_sizes,
    pair_truth_elongations as pair_truth_elongations,
)
from .hidden_effects import (
    MEMORY_EFFECTS as MEMORY_EFFECTS,
    OUT_OF_CATALOGUE as OUT_OF_CATALOGUE,
    cycling_humidity as cycling_humidity,
    effect_elongation as effect_elongation,
    humidity_climate as humidity_climate,
    stepped_humidity as stepped_humidity,
)
from .park import (
    SK78_TARGETS as SK78_TARGETS,
    Target as Target,
    TargetRow as TargetRow,
    park_protocol as park_protocol,
    sk78_qualitative_checks as sk78_qualitative_checks,
    sk78_targets_report as sk78_targets_report,
)
from .synthetic import (
    BUNDLED_COMPLIANCE as BUNDLED_COMPLIANCE,
    BUNDLED_EFFECT as BUNDLED_EFFECT,
    HIDDEN_EFFECT_DESIGN as HIDDEN_EFFECT_DESIGN,
    HIDDEN_EFFECTS as HIDDEN_EFFECTS,
    bundled_dataset as bundled_dataset,
    hidden_effect_dataset as hidden_effect_dataset,
    hidden_effect_model as hidden_effect_model,
    hidden_effect_protocol as hidden_effect_protocol,
    synthesize as synthesize,
    synthesize_history as synthesize_history,
    truth_elongations as truth_elongations,
)
