"""The kernels and constants that the tests and benchmarks reach below the public API.

`import jaxcable.internal as ji` gives the pieces a test needs to check a kernel on
its own (a Kelvin-Voigt step, the held-out split, the noise floor of the diagnosis,
the command line's option parsing) or to patch one (`monkeypatch.setattr(ji.drives,
...)`), without importing the private modules (`jaxcable._*`) one by one, as
optimistix's `optimistix.internal` does.

**This is not the stable API.** Names come and go with the implementation, without
notice; they are documented where they are defined. User code uses `jaxcable`,
`jaxcable.papers`, `jaxcable.cli`, `jaxcable.cdpr` and `jaxcable.states`.

Modules are re-exported where a test reads or patches several of their names (`ji.
synthetic.synthesize`, `ji.drives`); everything comes through the `__init__` of its
folder, as anywhere in the package (`tests/test_house.py`).
"""

# ruff: noqa: F401 (a module of re-exports; a module is named for its folder)

# Compilation cache and CPU loop kernels.
from ._cache import (
    cache_size as cache_size,
    exported_programs_dir as exported_programs_dir,
)

# The command line's pieces: option parsing and data reading, by module.
from ._cli import (
    common as cli_common,
    data as cli_data,
    demo as cli_demo,
    models as cli_models,
    parser as cli_parser,
)
from ._cpu_loops import (
    DEFAULT_LOOP_KERNEL_BYTES as DEFAULT_LOOP_KERNEL_BYTES,
    NO_LOOP_KERNELS_ENV as NO_LOOP_KERNELS_ENV,
    loop_kernels_disabled as loop_kernels_disabled,
    with_loop_kernel_option as with_loop_kernel_option,
)

# The diagnosis: its rule's thresholds, the held-out split and the noise floor.
from ._diagnose import (
    FAMILY_EXCESS as FAMILY_EXCESS,
    MAX_FLOOR_RATIO as MAX_FLOOR_RATIO,
    MIN_AUTOCORRELATION as MIN_AUTOCORRELATION,
    MIN_EXCESS as MIN_EXCESS,
    MIN_EXPLAINED_PCT as MIN_EXPLAINED_PCT,
    channel_noise as channel_noise,
    damage_integral as damage_integral,
    decide as decide,
    diverges as diverges,
    explained_pct as explained_pct,
    explained_rmse_pct as explained_rmse_pct,
    grid_step as grid_step,
    heldout_rmse as heldout_rmse,
    memory_library as memory_library,
    noise_level as noise_level,
    rate_of_change as rate_of_change,
    stack_of as stack_of,
    step_inputs as step_inputs,
    time_split as time_split,
    white_part as white_part,
)

# The drives: the rate solve and the simulation's passes, by module.
from ._drive import GRAVITY as GRAVITY, drives as drives, newton as newton, scan as scan

# The fit's kernels.
from ._fit import (
    LevenbergMarquardt as LevenbergMarquardt,
    cached_fit_kernels as cached_fit_kernels,
    fit_subset as fit_subset,
    serialize as fit_serialize,
    shared_layout as shared_layout,
    solver as fit_solver,
    with_jacobian_jvp as with_jacobian_jvp,
)

# Readers: the control of a test; the CSV writer's module.
from ._io import (
    control_name as control_name,
    csv as io_csv,
    resolve_control as resolve_control,
)

# The models: registry, kernels, parameter facts.
from ._models import (
    BY_CLI_NAME as BY_CLI_NAME,
    CLASSES_BY_NAME as CLASSES_BY_NAME,
    DEFAULT_CLI_MODEL as DEFAULT_CLI_MODEL,
    PARK_IDENTIFIABLE as PARK_IDENTIFIABLE,
    cli_name as cli_name,
    field_facts as field_facts,
    fields as model_fields,
    identifiable as identifiable,
    kernels as model_kernels,
    parameter_info as parameter_info,
    parameter_table as parameter_table,
    piao as piao,
)

# The papers' modules (protocols, calibration, synthetic data).
from ._papers import (
    calibration as calibration,
    hidden_effects as hidden_effects,
    park as park,
    synthetic as synthetic,
)

# The report.
from ._report import (
    model_elongations as model_elongations,
    write_report as write_report,
)

# Posterior diagnostics.
from ._uncertainty import bulk_ess as bulk_ess, split_rhat as split_rhat


# Single kernels and helpers read from their modules.
kelvin_voigt_step = model_kernels.kelvin_voigt_step
fit_parameters = model_fields.fit_parameters
model_document = fit_serialize.model_document
model_from_document = fit_serialize.model_from_document
second_test_indices = park.second_test_indices
