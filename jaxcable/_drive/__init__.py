from .analysis import (
    loop_energies as loop_energies,
    secant_stiffness as secant_stiffness,
)
from .controller import (
    GRAVITY as GRAVITY,
    ControllerState as ControllerState,
    LiveFiveElement as LiveFiveElement,
    controller_init as controller_init,
    controller_step as controller_step,
)
from .protocol import (
    Protocol as Protocol,
)
from .simulate import (
    CableState as CableState,
    check_history as check_history,
    init_state as init_state,
    simulate_force_history as simulate_force_history,
    simulate_rate_test as simulate_rate_test,
    step as step,
)
