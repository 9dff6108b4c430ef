"""The public simulations of one cable: [`jaxcable.step`][] (one force sample, for a
user's own scan) and [`jaxcable.simulate_force_history`][],
[`jaxcable.simulate_rate_test`][], [`jaxcable.simulate_elongation_history`][] (a whole
history, each a drive fed to the one scan kernel), with the checks of their inputs."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, Float

from .. import _checks
from .._cable import Cable, check_scalar_cable
from .._models import AbstractCableModel, StrainParts
from . import scan
from .drives import (
    ElongationDrive,
    ElongationSample,
    ForceDrive,
    ForceSample,
    RateDrive,
    default_solver,
    force_step,
)
from .newton import Newton
from .protocol import Protocol
from .state import (
    CableState,
    Trajectory,
)


class Simulation(eqx.Module):
    """How a simulation runs its history: the per-sample root solver, the
    checkpointing of the scan and what a failure does.

    **Fields:**

    - `solver`: a [`jaxcable.Newton`][] or any optimistix root finder, for the
        simulations that solve each sample (a rate-driven test: its times; an
        elongation history: its forces); None (the default): `jaxcable.Newton` with
        a tolerance set by the cable's dtype. A force history solves nothing and
        does not use it.
    - `checkpoint`: optional block length (samples) of a checkpointed scan, for the
        gradients of long histories in bounded memory (about sqrt(samples)).
    - `throw`: raise on failure (default). With `throw=False` the failure is
        returned in `Trajectory.result` (per cable under vmap).
    """

    solver: Newton | optx.AbstractRootFinder | None = None
    checkpoint: int | None = eqx.field(default=None, static=True)
    throw: bool = eqx.field(default=True, static=True)

    def __check_init__(self):
        if self.solver is not None and not isinstance(
            self.solver, Newton | optx.AbstractRootFinder
        ):
            raise ValueError(
                "Simulation: `solver` must be a jaxcable.Newton or an optimistix root "
                f"finder, got {type(self.solver).__name__}."
            )
        if self.checkpoint is not None:
            _checks.require_int("checkpoint", self.checkpoint, 1)
        if not isinstance(self.throw, bool):
            raise TypeError(f"Simulation: `throw` must be a bool, got {self.throw!r}.")

    def solver_for(self, cable: Cable) -> Newton | optx.AbstractRootFinder:
        """The solver of a simulation of `cable`: `solver`, or the default for the
        cable's dtype."""
        if self.solver is None:
            return default_solver(jnp.result_type(float, cable.length))
        return self.solver


def step(
    model: AbstractCableModel,
    cable: Cable,
    state: CableState,
    time: Float[ArrayLike, ""],
    force: Float[ArrayLike, ""],
) -> tuple[CableState, StrainParts]:
    """Advance one cable by one time-stamped force sample (no solve).

    A pure function for a user's own `lax.scan`, a controller, `jit`, `vmap` or
    `grad`. The force is linear between samples; the model is told the sign of the
    force change (`direction`). Every entry point that takes a force history
    ([`jaxcable.simulate_force_history`][], [`jaxcable.fit`][],
    [`jaxcable.controller_step`][], [`jaxcable.monte_carlo`][]) is this step in a
    scan, so all of them give the same elongations for the same history.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][].
    - `state`: the [`jaxcable.states.CableState`][] after the previous sample.
    - `time`: time of this sample, s (>= `state.time`).
    - `force`: force of this sample, N.

    **Returns:**

    `(new_state, parts)`: the new [`jaxcable.states.CableState`][] and the
    [`jaxcable.StrainParts`][] of this sample (strain = `parts.total`).
    """
    time = jnp.asarray(time, state.time.dtype)
    force = jnp.asarray(force, state.force.dtype)
    return force_step(model, cable, state, ForceSample(time, force, jnp.array(True)))


def simulate_force_history(
    model: AbstractCableModel,
    cable: Cable,
    time: Float[ArrayLike, " samples"],
    force: Float[ArrayLike, " samples"],
    *,
    mask: Bool[ArrayLike, " samples"] | None = None,
    method: Simulation = Simulation(),
) -> Trajectory:
    """Simulate a time-stamped force history, as a robot logs it.

    The force is linear between samples; the model is told the sign of each force
    change, with no threshold. The forces are used as given, with no deadband or
    smoothing, here as in every other entry point ([`jaxcable.step`][]): the same
    history gives the same elongations everywhere. The first sample is the initial
    condition reached from the unloaded cable at `time[0]` (a nonzero `force[0]` is
    applied instantly).

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][] (one cable; `jax.vmap` for a batch).
    - `time`: sample times, s, strictly increasing.
    - `force`: cable force at each sample, N, 0 <= force <= `cable.breaking_load`.
    - `mask`: optional, False marks padding samples (histories of different lengths
        in one vmapped batch); they leave the state unchanged.
    - `method`: a [`jaxcable.Simulation`][]: its `checkpoint` and `throw` (a force
        history solves nothing: its `solver` is not used).

    **Returns:**

    A [`jaxcable.Trajectory`][].
    """
    time, force, mask = check_history(cable, time, force, mask, "force")
    drive = ForceDrive(ForceSample(time, force, mask))
    return _run(drive, model, cable, method)


def simulate_rate_test(
    model: AbstractCableModel,
    cable: Cable,
    protocol: Protocol,
    *,
    method: Simulation = Simulation(),
) -> Trajectory:
    """Simulate a rate-driven test, as a tensile tester runs it (Park Section 4).

    The crosshead moves at `cable.speed`, so along each ramp the strain follows
    eps_kin(t) = eps_start +/- (v / L0) (t - t_start) (Park Eq. 6). The time t_i at
    which each force sample is reached is the root of model strain minus eps_kin
    (Park Eq. 6), found per sample by Newton's method (optimistix) inside the
    scan, vectorised under `vmap` and differentiated by the implicit function theorem.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][] (one cable; `jax.vmap` for a batch).
    - `protocol`: the [`jaxcable.Protocol`][] (ramps, holds, rests).
    - `method`: a [`jaxcable.Simulation`][]: the solver of the times (default
        `jaxcable.Newton` with a tolerance set by the dtype), `checkpoint` and
        `throw`.

    **Returns:**

    A [`jaxcable.Trajectory`][] whose `time` holds the solved sample times, s.
    """
    check_protocol(cable, protocol)
    check_dtypes(model, cable)
    drive = RateDrive(protocol, _method(method).solver_for(cable))
    return _run(drive, model, cable, method)


def simulate_elongation_history(
    model: AbstractCableModel,
    cable: Cable,
    time: Float[ArrayLike, " samples"],
    elongation: Float[ArrayLike, " samples"],
    *,
    mask: Bool[ArrayLike, " samples"] | None = None,
    method: Simulation = Simulation(),
) -> Trajectory:
    """Simulate a time-stamped elongation history (displacement control, e.g. a
    relaxation test): the force of each sample is solved by Newton's method.

    The branch follows the sign of the imposed elongation change; a hold keeps it.
    Where the imposed length is below the cable's zero-force length the cable is
    slack: the force is 0 and the strain is the model's free strain.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][].
    - `time`: sample times, s, strictly increasing.
    - `elongation`: imposed elongation, m.
    - `mask`: as in [`jaxcable.simulate_force_history`][].
    - `method`: a [`jaxcable.Simulation`][]: the solver of the forces (default
        `jaxcable.Newton` with a tolerance set by the dtype), `checkpoint` and
        `throw`.

    **Returns:**

    A [`jaxcable.Trajectory`][] whose `force` holds the solved forces, N.
    """
    time, elongation, mask = check_history(cable, time, elongation, mask, "elongation")
    check_dtypes(model, cable)
    samples = ElongationSample(time, elongation, mask)
    drive = ElongationDrive(samples, _method(method).solver_for(cable))
    return _run(drive, model, cable, method)


def _method(method: Simulation) -> Simulation:
    """`method`, checked to be a [`jaxcable.Simulation`][]."""
    if not isinstance(method, Simulation):
        raise TypeError(
            f"`method` must be a jaxcable.Simulation, got {type(method).__name__}."
        )
    return method


def _run(drive, model, cable, method: Simulation) -> Trajectory:
    """The drive's history through the scan kernel, as `method` says."""
    method = _method(method)
    return scan.run(drive, model, cable, method.throw, method.checkpoint)


def check_history(
    cable: Cable,
    time: Float[ArrayLike, " samples"],
    x: Float[ArrayLike, " samples"],
    mask: Bool[ArrayLike, " samples"] | None,
    xname: str,
) -> tuple[Float[Array, " samples"], Float[Array, " samples"], Bool[Array, " samples"]]:
    """Check a time-stamped history at the Python boundary (concrete inputs only;
    traced ones are flagged in the result of the scan) and convert it to arrays.

    **Arguments:**

    - `cable`: the [`jaxcable.Cable`][] (one cable).
    - `time`: sample times, s, finite and strictly increasing (on unmasked samples).
    - `x`: the driving history, finite on unmasked samples; a force (`xname`
        "force") is also checked >= 0 and below the cable's breaking load.
    - `mask`: optional, False at padding samples.
    - `xname`: the name of `x` in the error messages.

    **Returns:**

    `(time, x, mask)` as arrays of the cable's float dtype (`mask` all True when not
    given).

    **Raises:**

    `ValueError` naming the argument.
    """
    if _checks.is_concrete(cable):
        check_scalar_cable(cable)
    if _checks.is_concrete(time, x, mask):
        time = _checks.require_samples("time", time)
        x = _checks.require_samples(xname, x)
        if mask is not None:
            mask = _checks.require_samples("mask", mask)
        _checks.require_same_shape(time=time, **{xname: x}, mask=mask)
        m = None if mask is None else np.asarray(mask, bool)
        _checks.require_finite("time", time if m is None else np.asarray(time)[m])
        _checks.require_finite(xname, x if m is None else np.asarray(x)[m])
        _checks.require_increasing("time", time, m)
        if xname == "force":
            _checks.require_positive("force", x, allow_zero=True)
            if _checks.is_concrete(cable.breaking_load):
                _checks.require_below("force", x, cable.breaking_load, "breaking load")
    dtype = jnp.result_type(float, cable.length)
    time = jnp.asarray(time, dtype)
    x = jnp.asarray(x, dtype)
    mask = jnp.ones(time.shape, bool) if mask is None else jnp.asarray(mask, bool)
    return time, x, mask


def check_dtypes(model: AbstractCableModel, cable: Cable) -> None:
    """Check that a solved simulation's model and cable share one float dtype (the
    solve's iterates, in the cable's dtype, must not turn into the model's).

    **Raises:**

    `ValueError` naming the argument.
    """
    wanted = jnp.result_type(float, cable.length)
    for leaf in jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array)):
        if leaf.dtype != wanted:
            raise ValueError(
                f"`model` has {leaf.dtype} parameters but `cable` is {wanted}: a "
                "solved simulation needs one dtype; convert one of them, e.g. "
                "`jax.tree.map(lambda x: x.astype(jnp.float32), model)`."
            )


def check_protocol(cable: Cable, protocol: Protocol) -> None:
    """Check a protocol against a cable at the Python boundary (concrete inputs
    only): one 1-dimensional history, below the cable's breaking load.

    **Raises:**

    `ValueError` naming the argument.
    """
    if not isinstance(protocol, Protocol):
        raise ValueError(
            f"`protocol` must be a jaxcable.Protocol, got {type(protocol).__name__}."
        )
    if _checks.is_concrete(cable):
        check_scalar_cable(cable)
        if _checks.is_concrete(protocol.force):
            if jnp.ndim(protocol.force) != 1:
                raise ValueError(
                    f"`protocol.force` must be 1-dimensional, got shape "
                    f"{jnp.shape(protocol.force)}; vmap over a batch of protocols."
                )
            _checks.require_below(
                "protocol.force", protocol.force, cable.breaking_load, "breaking load"
            )
