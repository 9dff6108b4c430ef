"""Reproducing the papers, and the synthetic data sets built on them: a public
submodule, `from jaxcable import papers`, not part of the library's root namespace.

- Park et al.'s SK78 protocols and the numbers the paper prints (`SK78_TARGETS`,
  `park_protocol`), the model's errors against them (`sk78_targets_report`,
  `sk78_qualitative_checks`) and the calibration of the default parameters
  (`calibrate_sk78`);
- the synthetic data: tests with one hidden effect, for checking a diagnosis
  (`hidden_effect_dataset`, `hidden_effect_model`, `HIDDEN_EFFECTS`; effects outside
  the diagnosis catalogue, `OUT_OF_CATALOGUE`, with `truth_elongations`; among them
  the effects with a state of their own, `MEMORY_EFFECTS`), tests with two hidden
  catalogue effects at once (`hidden_pair_dataset`, `hidden_pair_model`,
  `HIDDEN_PAIRS`, `pair_sizes`, `pair_truth_elongations`), and the bundled data set
  of `make demo` (`bundled_dataset`).
"""

from ._papers import (
    HIDDEN_EFFECTS as HIDDEN_EFFECTS,
    HIDDEN_PAIRS as HIDDEN_PAIRS,
    MEMORY_EFFECTS as MEMORY_EFFECTS,
    OUT_OF_CATALOGUE as OUT_OF_CATALOGUE,
    SK78_START as SK78_START,
    SK78_TARGETS as SK78_TARGETS,
    Calibration as Calibration,
    bundled_dataset as bundled_dataset,
    calibrate_sk78 as calibrate_sk78,
    hidden_effect_dataset as hidden_effect_dataset,
    hidden_effect_model as hidden_effect_model,
    hidden_effect_protocol as hidden_effect_protocol,
    hidden_pair_dataset as hidden_pair_dataset,
    hidden_pair_model as hidden_pair_model,
    pair_sizes as pair_sizes,
    pair_truth_elongations as pair_truth_elongations,
    park_protocol as park_protocol,
    sk78_qualitative_checks as sk78_qualitative_checks,
    sk78_targets_report as sk78_targets_report,
    synthesize as synthesize,
    synthesize_history as synthesize_history,
    truth_elongations as truth_elongations,
)
