"""What the robot does and what it is made of: the task, hours of pick-and-place
([`jaxcable.cdpr.Scenario`][], [`jaxcable.cdpr.pick_and_place`][]), and the "real"
cables of the simulated robot, drawn around the controller's model with an effect it
lacks ([`jaxcable.cdpr.real_cables`][])."""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from .._arrays import field_array
from .._models import AbstractCableModel, IntegratedModel, TerminationCompliance
from .._montecarlo import IndependentParameters, LogNormal
from .robot import NOMINAL


class Scenario(eqx.Module):
    """A sampled motion: desired end-effector positions and the payload carried.

    **Fields:** `time` (s, `(T,)`), `position` (m, `(T, 3)`), `payload` (kg, `(T,)`).
    """

    time: Float[Array, " T"] = eqx.field(converter=field_array)
    position: Float[Array, "T 3"] = eqx.field(converter=field_array)
    payload: Float[Array, " T"] = eqx.field(converter=field_array)

    def __check_init__(self):
        T = jnp.shape(self.time)
        if (
            len(T) != 1
            or jnp.shape(self.position) != (*T, 3)
            or jnp.shape(self.payload) != T
        ):
            raise ValueError(
                f"Scenario: `time` (T,), `position` (T, 3), `payload` (T,) expected, "
                f"got {T}, {jnp.shape(self.position)}, {jnp.shape(self.payload)}."
            )

    def __getitem__(self, index) -> "Scenario":
        return Scenario(self.time[index], self.position[index], self.payload[index])


HOME = (0.0, 0.0, 2.2)
PICK = (-1.0, -0.9, 0.9)
PLACE = (1.0, 0.9, 1.3)
PAYLOADS = (65.0, 30.0, 50.0, 15.0, 65.0, 40.0, 55.0, 25.0)
# One cycle, s: home -> pick, dwell (grasp), pick -> place, dwell (release),
# place -> home, idle.
_SEGMENTS = (("move", 8.0), ("grasp", 6.0), ("move", 10.0), ("release", 6.0))
_SEGMENTS += (("move", 8.0), ("idle", 22.0))


def _minimum_jerk(s):
    return s**3 * (10 - 15 * s + 6 * s**2)


def pick_and_place(
    hours: float = 2.0,
    *,
    dt: float = 1.0,
    payloads=PAYLOADS,
    home=HOME,
    pick=PICK,
    place=PLACE,
) -> Scenario:
    """Hours of pick-and-place: a 60 s cycle repeated, each cycle carrying the next
    payload of `payloads` (kg, cycled).

    A cycle: home -> pick (8 s), grasp (6 s: the payload is taken over 2 s in the
    middle), pick -> place (10 s), release (6 s), place -> home (8 s), idle at home
    (22 s). Moves follow a minimum-jerk profile on straight lines.

    **Arguments:**

    - `hours`: duration, h.
    - `dt`: sample period, s (the controller and the creep models run at 1/dt).
    - `payloads`: the payload of each cycle, kg (0 to 65 kg in Piao's robot).
    - `home`, `pick`, `place`: positions, m.

    **Returns:**

    A [`jaxcable.cdpr.Scenario`][].
    """
    if not (hours > 0 and dt > 0):
        raise ValueError(f"`hours` and `dt` must be positive, got {hours}, {dt}.")
    payloads = np.asarray(payloads, float)
    if payloads.ndim != 1 or payloads.size == 0 or np.any(payloads < 0):
        raise ValueError(f"`payloads` must be non-negative masses, got {payloads}.")
    home, pick, place = (np.asarray(p, float) for p in (home, pick, place))
    period = sum(d for _, d in _SEGMENTS)
    time = np.arange(0.0, hours * 3600.0 + 0.5 * dt, dt)
    cycle = np.floor(time / period).astype(int)
    phase = time - cycle * period
    mass = payloads[cycle % payloads.size]
    position = np.empty((time.size, 3))
    payload = np.empty(time.size)
    route = (home, pick, pick, place, place, home, home)
    start = 0.0
    for k, (kind, duration) in enumerate(_SEGMENTS):
        inside = (phase >= start) & (phase < start + duration)
        s = (phase[inside] - start) / duration
        a, b = route[k], route[k + 1]
        position[inside] = a + _minimum_jerk(s)[:, None] * (b - a)
        ramp = np.clip((s - 1 / 3) * 3, 0.0, 1.0)  # the middle third of the dwell
        held = {"grasp": ramp, "move": k == 2, "release": 1 - ramp, "idle": 0.0}[kind]
        payload[inside] = mass[inside] * held
        start += duration
    return Scenario(time, position, payload)


# ----------------------------------------------------------------------------------
# The "real" cables.

# The parameters drawn for the real cables: every modulus, viscosity and time of the
# integrated model (the hardening and long-term-recovery laws keep their values).
REAL_PARAMETERS = ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r", "t_e")


def real_cables(
    key: PRNGKeyArray,
    *,
    num_cables: int = 8,
    relative_std: float = 0.05,
    compliance: float = 2e-5,
    model: IntegratedModel = NOMINAL,
) -> AbstractCableModel:
    """The cables of the simulated "real" robot: one parameter set per cable drawn
    around the controller's model, plus an effect the controller's model lacks.

    Each cable's `REAL_PARAMETERS` are drawn log-normally (median: `model`'s value,
    standard deviation of the log `relative_std`: the fit's uncertainty and the
    cable-to-cable scatter), with [`jaxcable.IndependentParameters`][]; the cables
    are then wrapped in [`jaxcable.TerminationCompliance`][], a length-independent
    series compliance (splices, the pulley and the winch drum) that none of the
    compensation models has.

    **Returns:**

    A `TerminationCompliance` whose arrays have a leading axis of `num_cables`
    (use with `per_cable=True`).
    """
    sampler = IndependentParameters(
        model,
        {n: LogNormal(getattr(model, n), relative_std) for n in REAL_PARAMETERS},
    )
    drawn = jax.vmap(sampler.draw)(jax.random.split(key, num_cables))
    broadcast = jtu.tree_map(
        lambda x: (
            jnp.broadcast_to(x, (num_cables, *jnp.shape(x)[1:]))
            if jnp.ndim(x) == 0
            else x
        ),
        drawn,
    )
    return TerminationCompliance(broadcast, jnp.full(num_cables, compliance))
