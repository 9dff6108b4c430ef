"""Driving a cable model through a history: protocols, the one scan kernel and its
drives (force, rate, elongation), the drive of a measured test as a value, the
controller API and cycle analysis."""

from .analysis import (
    loop_energies as loop_energies,
    secant_stiffness as secant_stiffness,
    split_cycles as split_cycles,
)
from .controller import (
    GRAVITY as GRAVITY,
    ControllerState as ControllerState,
    LiveFiveElement as LiveFiveElement,
    controller_init as controller_init,
    controller_step as controller_step,
)
from .driven import (
    ELONGATION_DRIVEN as ELONGATION_DRIVEN,
    FORCE_DRIVEN as FORCE_DRIVEN,
    TEST_DRIVES as TEST_DRIVES,
    AbstractTestDrive as AbstractTestDrive,
    ChannelDrive as ChannelDrive,
    DriveSpec as DriveSpec,
    as_test_drive as as_test_drive,
)
from .drives import (
    ElongationDrive as ElongationDrive,
    ElongationSample as ElongationSample,
    default_solver as default_solver,
)
from .newton import ROBUST as ROBUST, Newton as Newton
from .protocol import (
    Protocol as Protocol,
)
from .scan import Solve as Solve
from .simulate import (
    Simulation as Simulation,
    check_history as check_history,
    simulate_elongation_history as simulate_elongation_history,
    simulate_force_history as simulate_force_history,
    simulate_rate_test as simulate_rate_test,
    step as step,
)
from .state import (
    CableState as CableState,
    Trajectory as Trajectory,
    init_state as init_state,
)
