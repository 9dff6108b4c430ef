import importlib.metadata

# Before anything else (nothing here computes): XLA reads its flags when JAX first
# computes, and jaxcable's scans want their CPU loop kernels (`_cpu_loops`).
from ._cpu_loops import enable_at_import as _enable_at_import


_enable_at_import()

from . import states as states
from ._cable import (
    DEFAULT_BREAKING_LOAD_N as DEFAULT_BREAKING_LOAD_N,
    DEFAULT_BREAKING_STRAIN as DEFAULT_BREAKING_STRAIN,
    Cable as Cable,
    default_breaking_load as default_breaking_load,
)
from ._cache import (
    clear_compilation_cache as clear_compilation_cache,
    enable_compilation_cache as enable_compilation_cache,
)
from ._cpu_loops import (
    LoopKernelWarning as LoopKernelWarning,
    enable_cpu_loop_kernels as enable_cpu_loop_kernels,
)
from ._diagnose import (
    Candidate as Candidate,
    CandidateSearch as CandidateSearch,
    Diagnosis as Diagnosis,
    Discovery as Discovery,
    DiscoveryResult as DiscoveryResult,
    HeldOut as HeldOut,
    diagnose as diagnose,
    discover as discover,
    residual_structure as residual_structure,
)
from ._drive import (
    ELONGATION_DRIVEN as ELONGATION_DRIVEN,
    FORCE_DRIVEN as FORCE_DRIVEN,
    TEST_DRIVES as TEST_DRIVES,
    AbstractTestDrive as AbstractTestDrive,
    LiveFiveElement as LiveFiveElement,
    Newton as Newton,
    Protocol as Protocol,
    Simulation as Simulation,
    Trajectory as Trajectory,
    as_test_drive as as_test_drive,
    controller_init as controller_init,
    controller_step as controller_step,
    init_state as init_state,
    loop_energies as loop_energies,
    secant_stiffness as secant_stiffness,
    simulate_elongation_history as simulate_elongation_history,
    simulate_force_history as simulate_force_history,
    simulate_rate_test as simulate_rate_test,
    split_cycles as split_cycles,
    step as step,
)
from ._fit import (
    FitResult as FitResult,
    IdentifiabilityWarning as IdentifiabilityWarning,
    PaddedTests as PaddedTests,
    StartMovedWarning as StartMovedWarning,
    StartScaling as StartScaling,
    fit as fit,
    fit_each as fit_each,
    make_loss as make_loss,
    model_responses as model_responses,
    pad_tests as pad_tests,
    residuals as residuals,
    retardation_times as retardation_times,
    scaled_start as scaled_start,
    start_failure as start_failure,
    start_scaling as start_scaling,
)
from ._io import (
    ControlDetection as ControlDetection,
    MetadataConflictWarning as MetadataConflictWarning,
    ReadOptions as ReadOptions,
    SlackReport as SlackReport,
    SlackStretch as SlackStretch,
    TestData as TestData,
    detect_control as detect_control,
    mask_slack as mask_slack,
    read_csv as read_csv,
    read_test as read_test,
    write_csv as write_csv,
)
from ._models import (
    COVARIATE_EXTENSIONS as COVARIATE_EXTENSIONS,
    EXTENSIONS as EXTENSIONS,
    PIAO_TABLE3 as PIAO_TABLE3,
    AbstractCableModel as AbstractCableModel,
    AbstractExtension as AbstractExtension,
    BeddingIn as BeddingIn,
    BoucWenModel as BoucWenModel,
    BurgersModel as BurgersModel,
    CovariateShift as CovariateShift,
    CovariateStrain as CovariateStrain,
    DiscoveredTerm as DiscoveredTerm,
    FindleyModel as FindleyModel,
    FiveElementModel as FiveElementModel,
    Hardening as Hardening,
    Hereditary as Hereditary,
    HookeModel as HookeModel,
    IntegratedModel as IntegratedModel,
    MechanoSorptive as MechanoSorptive,
    ParameterSurface as ParameterSurface,
    SecondRetardation as SecondRetardation,
    SensorDrift as SensorDrift,
    StrainParts as StrainParts,
    StressNonlinearCreep as StressNonlinearCreep,
    TemperatureShift as TemperatureShift,
    TemperatureShiftWLF as TemperatureShiftWLF,
    TerminationCompliance as TerminationCompliance,
    log_shift_arrhenius as log_shift_arrhenius,
    log_shift_wlf as log_shift_wlf,
    piao_five_element as piao_five_element,
    with_data_reference as with_data_reference,
)
from ._montecarlo import (
    AbstractDistribution as AbstractDistribution,
    AbstractParameterSampler as AbstractParameterSampler,
    CorrelatedParameters as CorrelatedParameters,
    ForceHistory as ForceHistory,
    IndependentParameters as IndependentParameters,
    LogNormal as LogNormal,
    MonteCarlo as MonteCarlo,
    MonteCarloResult as MonteCarloResult,
    Normal as Normal,
    Uniform as Uniform,
    monte_carlo as monte_carlo,
)
from ._problem import (
    LeastSquares as LeastSquares,
    Problem as Problem,
    StreamingLeastSquares as StreamingLeastSquares,
)
from ._progress import (
    AbstractProgressMeter as AbstractProgressMeter,
    CallbackProgressMeter as CallbackProgressMeter,
    NoProgressMeter as NoProgressMeter,
    TextProgressMeter as TextProgressMeter,
)
from ._report import write_diagnosis_report as write_diagnosis_report
from ._results import RESULTS as RESULTS
from ._uncertainty import (
    NUTS as NUTS,
    DesignedTest as DesignedTest,
    DiscriminatingTest as DiscriminatingTest,
    Posterior as Posterior,
    TestBudget as TestBudget,
    TestDesign as TestDesign,
    design_discriminating_test as design_discriminating_test,
    design_test as design_test,
    sample_posterior as sample_posterior,
)


__version__ = importlib.metadata.version("jaxcable")
