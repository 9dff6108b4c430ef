"""An 8-cable suspended robot with creep-compensated winch lengths: the example of how
jaxcable drops into a JAX control loop (`notebooks/05_cdpr.ipynb`). A public
submodule, `from jaxcable import cdpr`, not part of the library's root namespace.

Every function is pure JAX: a whole run (hours of pick-and-place) is one jitted
`lax.scan`, and `jax.grad` goes through it.

- `robot`: the robot's geometry, tension distribution and kinematics;
- `scenario`: the pick-and-place task and the "real" cables;
- `run`: the closed loop and the comparison of compensation models;
- `tuning`: derivatives through the closed loop and gain tuning;
- `estimator`, `state`, `horizon`, `signals`, `online`: a robot that calibrates its own
    cables (an online estimator of each cable's parameters beside the controller,
    its moving-horizon re-linearisation, what it measures, and the closed loop it
    compensates).
"""

from .estimator import (
    DEFAULT_PARAMETERS as DEFAULT_PARAMETERS,
    OnlineEstimator as OnlineEstimator,
)
from .online import (
    OnlineRun as OnlineRun,
    Sensors as Sensors,
    simulate_online as simulate_online,
)
from .robot import (
    BREAKING_LOAD as BREAKING_LOAD,
    DIAMETER as DIAMETER,
    NOMINAL as NOMINAL,
    STRAIN_RATE as STRAIN_RATE,
    Robot as Robot,
    forward_kinematics as forward_kinematics,
    tension_distribution as tension_distribution,
)
from .run import (
    FIVE_ELEMENT as FIVE_ELEMENT,
    HOOKE as HOOKE,
    RobotRun as RobotRun,
    compare as compare,
    compensation_models as compensation_models,
    removed as removed,
    simulate_robot as simulate_robot,
)
from .scenario import (
    HOME as HOME,
    PAYLOADS as PAYLOADS,
    PICK as PICK,
    PLACE as PLACE,
    REAL_PARAMETERS as REAL_PARAMETERS,
    Scenario as Scenario,
    pick_and_place as pick_and_place,
    real_cables as real_cables,
    real_sensors as real_sensors,
)
from .signals import Fix as Fix, fix_prediction as fix_prediction
from .state import (
    EstimatorState as EstimatorState,
    interval_covers as interval_covers,
)
from .tuning import (
    GainTuning as GainTuning,
    errors_and_jacobian as errors_and_jacobian,
    loss_and_grad as loss_and_grad,
    position_loss as position_loss,
    tune_gain as tune_gain,
)
