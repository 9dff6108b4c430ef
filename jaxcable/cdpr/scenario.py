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
    bedded_in=(),
    bedded_ratio: float = 1.5,
) -> AbstractCableModel:
    """The cables of the simulated "real" robot: one parameter set per cable drawn
    around the controller's model, plus an effect the controller's model lacks.

    Each cable's `REAL_PARAMETERS` are drawn log-normally (median: `model`'s value,
    standard deviation of the log `relative_std`: the fit's uncertainty and the
    cable-to-cable scatter), with [`jaxcable.IndependentParameters`][]; the cables
    are then wrapped in [`jaxcable.TerminationCompliance`][], a length-independent
    series compliance (splices, the pulley and the winch drum) that none of the
    compensation models has. The cables listed in `bedded_in` carry a rope already
    bedded in: its reloading modulus E1r is `bedded_ratio` times its drawn E1c (Park's
    constructional elongation taken out, so that reloads are stiffer than the first
    loading).

    **Arguments:**

    - `key`: the draw's key.
    - `num_cables`: n.
    - `relative_std`: the standard deviation of each parameter's log (0.3: 30 %).
    - `compliance`: the terminations' series compliance, m/N.
    - `model`: the median model.
    - `bedded_in`: indices of the bedded-in cables (none by default).
    - `bedded_ratio`: their E1r / E1c (> 1).

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
    bedded = np.zeros(num_cables, bool)
    bedded[list(bedded_in)] = True
    if bedded.any():
        if not bedded_ratio > 1:
            raise ValueError(f"`bedded_ratio` must be > 1, got {bedded_ratio}.")
        E1r = jnp.where(bedded, bedded_ratio * broadcast.E1c, broadcast.E1r)
        broadcast = eqx.tree_at(lambda m: m.E1r, broadcast, E1r)
    return TerminationCompliance(broadcast, jnp.full(num_cables, compliance))


def real_sensors(
    key: PRNGKeyArray,
    scenario: Scenario,
    num_cables: int = 8,
    *,
    fix_every: float = 10.0,
    fix_noise: float = 0.5e-3,
    force_noise: float = 0.5,
    force_drift: float = 1.0,
    dropouts=(),
    stuck=(),
):
    """The imperfect sensors of the simulated "real" robot, for
    [`jaxcable.cdpr.simulate_online`][]: noisy, drifting load cells, a load cell that
    sticks, noisy position fixes at a fixed period with dropouts.

    **Arguments:**

    - `key`: the draw's key.
    - `scenario`: the [`jaxcable.cdpr.Scenario`][] (its time, s).
    - `num_cables`: n.
    - `fix_every`: s between position fixes (none at the start).
    - `fix_noise`: standard deviation of each coordinate of a fix, m.
    - `force_noise`: standard deviation of the load cells' white noise, N.
    - `force_drift`: standard deviation of each load cell's drift rate, N/h (a
        linear drift from zero at the start, its rate drawn per cell).
    - `dropouts`: `((start, duration), ...)`, s: no fix in these spans.
    - `stuck`: `((cable, start, duration), ...)`, s: that load cell repeats its last
        reading in that span.

    **Returns:**

    A [`jaxcable.cdpr.Sensors`][].
    """
    from .online import Sensors  # the loop's module imports this one

    if not (fix_every > 0 and fix_noise >= 0 and force_noise >= 0):
        raise ValueError(
            "`fix_every` must be positive and `fix_noise`, `force_noise` >= 0."
        )
    time = np.asarray(scenario.time)
    T = time.size
    t = time - time[0]
    k_fix, k_noise, k_drift = jax.random.split(key, 3)
    period = np.round(fix_every / np.median(np.diff(time))).astype(int) if T > 1 else 1
    fix = (np.arange(T) % max(period, 1) == 0) & (np.arange(T) > 0)
    for start, duration in dropouts:
        fix &= ~((t >= start) & (t < start + duration))
    dtype = jnp.result_type(float, scenario.time)
    rate = force_drift / 3600.0 * jax.random.normal(k_drift, (num_cables,), dtype)
    noise = force_noise * jax.random.normal(k_noise, (T, num_cables), dtype)
    held = np.zeros((T, num_cables), bool)
    for cable, start, duration in stuck:
        held[:, cable] |= (t >= start) & (t < start + duration)
    return Sensors(
        fix=jnp.asarray(fix),
        fix_error=fix_noise * jax.random.normal(k_fix, (T, 3), dtype),
        force_error=noise + jnp.asarray(t, dtype)[:, None] * rate[None, :],
        stuck=jnp.asarray(held),
    )
