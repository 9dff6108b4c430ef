"""Controller-facing API: the creep of a set of cables (a robot's 4, 8, ... cables of
different lengths) predicted sample by sample from their measured forces, as pure
functions over an explicit state, for a user's own `jit`-ed, `lax.scan`-ned and
differentiated control loop.

The kernel is [`jaxcable.step`][] for one cable (force-driven: no solve), `jax.vmap`-ed
over the set; nothing is re-implemented here."""

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .. import _checks
from .._cable import CABLE_FIELDS, Cable
from .._models import (
    PIAO_TABLE3,
    AbstractCableModel,
    AbstractFiveElement,
    FiveElementModel,
    FiveElementState,
    ParameterSurface,
    StrainParts,
    setting,
    table1_field,
)
from .._results import RESULTS
from .simulate import step
from .state import CableState, init_state


GRAVITY = 9.80665  # m/s^2, standard gravity


# ----------------------------------------------------------------------------------
# Piao's five-element model with its payload/length surface evaluated live.


class LiveFiveElement(AbstractFiveElement):
    r"""Piao et al.'s five-element model whose spring moduli follow the payload and
    the cable length sample by sample (Piao Eq. 5, Tables 1 and 3).

    At every sample its parameters are those of
    [`jaxcable.piao_five_element`][]`(force / gravity, cable.length)`: the payload is
    the mass the cable carries, F / g (Piao measured each cable with a hanging mass,
    Section 2.2), and the length is the cable's current free length (`cable.length`,
    which a robot passes anew at each step as its winches pay out and reel in). The
    state and the exact Boltzmann superposition are those of
    [`jaxcable.FiveElementModel`][]; only E_L1 and E_UL1 = `surface(m, l)` change
    between samples (Piao's Table 2 is lost, see [`jaxcable.piao_five_element`][]).
    With [`jaxcable.PIAO_TABLE3`][] the spring is practically rigid (E_L1 >= 9e11 Pa
    for 0-70 kg on 5-9 m cables), so the live surface changes the strain by about
    1e-6 (12 µm on the 8-cable example's 7-9 m cables, against a fixed E_L1): the
    creep of this model is carried by the Table 1 Kelvin-Voigt elements.

    **Fields:**

    - `surface`: the E_L1 = E_UL1 surface (default [`jaxcable.PIAO_TABLE3`][]).
    - `gravity`: g, m/s^2, to read a force as a payload mass (> 0; a setting, not
        fitted).
    - `E_L2`, `E_L3`, `eta_L2`, `eta_L3`: Piao Table 1 (Pa, Pa s), also used for
        unloading (E_UL2, ... are set equal: the lost Table 2).
    """

    CLI_NAME = "live-five-element"

    surface: ParameterSurface = PIAO_TABLE3
    gravity: Float[Array, ""] = setting(GRAVITY, unit="m/s^2")
    E_L2: Float[Array, ""] = table1_field("E_L2")
    E_L3: Float[Array, ""] = table1_field("E_L3")
    eta_L2: Float[Array, ""] = table1_field("eta_L2")
    eta_L3: Float[Array, ""] = table1_field("eta_L3")

    def parameter_sets(self, force: Float[Array, ""], length: Float[Array, ""]):
        """Both sets (E1, E2, eta2, E3, eta3): E1 = `surface(force / gravity,
        length)`, the others Piao's Table 1."""
        E_1 = self.surface(force / self.gravity, length)
        both = (E_1, self.E_L2, self.eta_L2, self.E_L3, self.eta_L3)
        return both, both

    def model_at(self, force: Float[Array, ""], length: Float[Array, ""]):
        """The [`jaxcable.FiveElementModel`][] for this force (N) and length (m)."""
        return FiveElementModel.from_sets(*self.parameter_sets(force, length))

    def init(self, cable: Cable) -> FiveElementState:
        dtype = jnp.result_type(float, self.E_L2, cable.length)
        return self.model_at(jnp.zeros((), dtype), cable.length).init(cable)

    def check(self, cable: Cable) -> RESULTS:
        # The surface at 0 kg is checked here; each sample's E_L1 is checked in advance
        # (a non-positive modulus gives a non-finite or negative strain).
        return self.model_at(jnp.zeros_like(cable.length), cable.length).check(cable)

    def flagged(self, loading, parts: StrainParts) -> StrainParts:
        # Outside the surface's domain the strain is flagged as non-physical (NaN).
        bad = ~(loading[0] > 0)
        return jtu.tree_map(lambda p: jnp.where(bad, jnp.nan, p), parts)


# ----------------------------------------------------------------------------------
# A set of cables.


# XLA's CPU runtime runs an executable's kernels one after the other, on the calling
# thread, when every buffer is at most this many bytes; above it, it runs independent
# kernels concurrently on its thread pool, which for a step this small costs more
# than it saves (benchmarks/controller.py). The packed state is
# therefore split into chunks of at most this size.
_SEQUENTIAL_BUFFER_BYTES = 512
_MAX_CHUNKS = 8


def _chunk_columns(n: int, k: int, itemsize: int) -> int:
    columns = max(1, _SEQUENTIAL_BUFFER_BYTES // (n * itemsize))
    # Many cables: the kernels are large enough to gain from the thread pool.
    return k if -(-k // columns) > _MAX_CHUNKS else columns


class ControllerState(eqx.Module):
    """The state of a set of cables inside a controller: one [`jaxcable.states.CableState`][]
    per cable (the model's state, the last sample's time, force and strain, the first
    failure), packed into a few arrays of shape `(n, k_i)`.

    Packed because a real-time loop calls the jitted step from Python at kHz rates,
    and `jax.jit` pays for every array of its arguments and results at each call
    (benchmarks/controller.py): a `CableState` of the integrated model has 20 arrays.
    The columns are split into chunks of at most 512 bytes, the size up to which
    XLA's CPU runtime executes the step's kernels sequentially on the calling thread
    (for 8 cables in float64: 3 arrays). Integer fields (the branch, the result) are
    stored as floats, exactly (the float format holds small integers exactly).

    `per_cable` (static) says whether the cables' model carries one parameter set
    per cable (see [`jaxcable.controller_init`][]).

    **Properties:** `cables` (the stacked [`jaxcable.states.CableState`][], fields of shape
    `(n, ...)`), `time` (s), `forces` (N), `strain`, `result` (one
    [`jaxcable.RESULTS`][] per cable), `num_cables`.
    """

    packed: tuple[Float[Array, "n _k"], ...]
    treedef: Any = eqx.field(static=True)
    shapes: tuple[tuple[int, ...], ...] = eqx.field(static=True)
    dtypes: tuple[str, ...] = eqx.field(static=True)
    per_cable: bool = eqx.field(default=False, static=True)

    @property
    def num_cables(self) -> int:
        return int(jnp.shape(self.packed[0])[0])

    @property
    def cables(self) -> CableState:
        n = self.num_cables
        packed = jnp.concatenate(self.packed, axis=1)
        leaves, start = [], 0
        for shape, dtype in zip(self.shapes, self.dtypes):
            size = math.prod(shape)
            x = packed[:, start : start + size].reshape(n, *shape)
            if jnp.issubdtype(dtype, jnp.integer):
                x = jnp.round(x)
            leaves.append(x.astype(dtype))
            start += size
        return jtu.tree_unflatten(self.treedef, leaves)

    @property
    def time(self) -> Float[Array, ""]:
        """Time of the last sample, s."""
        return self.cables.time[0]

    @property
    def forces(self) -> Float[Array, " n"]:
        """Forces of the last sample, N."""
        return self.cables.force

    @property
    def strain(self) -> Float[Array, " n"]:
        """Strains of the last sample (elongation / length)."""
        return self.cables.strain

    @property
    def result(self) -> RESULTS:
        """One [`jaxcable.RESULTS`][] per cable (the first failure so far)."""
        return self.cables.result


def _pack(states: CableState, per_cable: bool) -> ControllerState:
    leaves, treedef = jtu.tree_flatten(states)
    n = jnp.shape(states.time)[0]
    dtype = states.time.dtype
    packed = jnp.concatenate([jnp.reshape(x, (n, -1)).astype(dtype) for x in leaves], 1)
    k = packed.shape[1]
    columns = _chunk_columns(n, k, jnp.dtype(dtype).itemsize)
    return ControllerState(
        packed=tuple(packed[:, i : i + columns] for i in range(0, k, columns)),
        treedef=treedef,
        shapes=tuple(tuple(jnp.shape(x)[1:]) for x in leaves),
        dtypes=tuple(jnp.dtype(x.dtype).name for x in leaves),
        per_cable=per_cable,
    )


def _num_cables(cables: Cable) -> int:
    if not isinstance(cables, Cable):
        raise ValueError(
            f"`cables` must be a jaxcable.Cable (fields of shape (n,)), got "
            f"{type(cables).__name__}."
        )
    shapes = {
        name: jnp.shape(getattr(cables, name))
        for name in CABLE_FIELDS
        if getattr(cables, name) is not None
    }
    sizes = {s[0] for s in shapes.values() if len(s) == 1}
    if any(len(s) > 1 for s in shapes.values()) or len(sizes) != 1:
        desc = ", ".join(f"{k} {v}" for k, v in shapes.items())
        raise ValueError(
            "`cables` must describe a set of n cables: `length` of shape (n,) and the "
            f"other fields of shape (n,) or () (broadcast); got {desc}."
        )
    (n,) = sizes
    if n == 0:
        raise ValueError("`cables` is empty: a controller needs at least one cable.")
    return n


def _broadcast_cables(cables: Cable, n: int) -> Cable:
    # tree_map rebuilds the Module without calling __init__ (no re-validation).
    return jtu.tree_map(lambda x: jnp.broadcast_to(x, (n,)), cables)


def _model_axes(model, n: int, per_cable: bool):
    if not isinstance(model, AbstractCableModel):
        raise ValueError(
            f"`model` must be a jaxcable model, got {type(model).__name__}."
        )
    if not per_cable:
        return None
    for path, leaf in jtu.tree_flatten_with_path(model)[0]:
        if eqx.is_array(leaf) and (jnp.ndim(leaf) == 0 or jnp.shape(leaf)[0] != n):
            raise ValueError(
                f"`model` with `per_cable=True` needs a leading axis of size {n} (one "
                f"parameter set per cable) on every array; "
                f"`model{jtu.keystr(path)}` has shape {jnp.shape(leaf)}."
            )
    return 0


def _check_state(state, n: int) -> None:
    if not isinstance(state, ControllerState):
        raise ValueError(
            f"`state` must be a ControllerState (from controller_init), got "
            f"{type(state).__name__}."
        )
    if state.num_cables != n:
        raise ValueError(
            f"`state` holds {state.num_cables} cables but `cables` has {n}."
        )


def controller_init(
    model: AbstractCableModel,
    cables: Cable,
    time: Float[ArrayLike, ""] = 0.0,
    *,
    per_cable: bool = False,
) -> ControllerState:
    """The state of a set of new, unloaded cables at `time` (s).

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][], shared by every cable, or with
        `per_cable=True` a model whose every array has a leading axis of size n (one
        parameter set per cable, e.g. `jax.vmap(sampler.draw)(keys)`).
    - `cables`: a [`jaxcable.Cable`][] whose `length` has shape `(n,)` (the other
        fields `(n,)` or scalars, broadcast).
    - `time`: the time of the initial state, s.
    - `per_cable`: whether `model` carries one parameter set per cable (static);
        the state remembers it for [`jaxcable.controller_step`][].

    **Returns:**

    A [`jaxcable.states.ControllerState`][].
    """
    n = _num_cables(cables)
    axis = _model_axes(model, n, per_cable)
    if _checks.is_concrete(time):
        time = _checks_time(time)
    cables = _broadcast_cables(cables, n)
    states = jax.vmap(init_state, in_axes=(axis, 0, None))(model, cables, time)
    return _pack(states, per_cable)


def _checks_time(time):
    t = np.asarray(time)
    if t.shape != ():
        raise ValueError(f"`time` must be a scalar (s), got shape {t.shape}.")
    _checks.require_finite("time", t)
    return time


def controller_step(
    model: AbstractCableModel,
    cables: Cable,
    state: ControllerState,
    time: Float[ArrayLike, ""],
    forces: Float[ArrayLike, " n"],
    *,
    throw: bool = True,
) -> tuple[ControllerState, Float[Array, " n"]]:
    """Advance a set of cables by one time-stamped sample of their forces and return
    their predicted elongations.

    A pure function, written for one cable ([`jaxcable.step`][]) and `jax.vmap`-ed
    over the set: use it inside `jax.jit`, `jax.lax.scan` and `jax.grad` (with respect
    to the forces, the lengths or the model's parameters). Everything that may change
    during a motion is an argument of each call, not part of the state:

    - `cables.length` is each cable's current free length (m), which the winches
        change; the model's state is a strain (dimensionless), so a cable's elongation
        is its strain times its length at this sample (the whole free length is
        treated as one material point: the segments reeled onto or off the drum
        are assumed to share the state);
    - `model` may be rebuilt at every step (parameters updated online, or a model
        whose parameters are functions of the load and the length, such as
        [`jaxcable.LiveFiveElement`][], Piao's surfaces evaluated live).

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][], shared by the cables, or one
        parameter set per cable where the state was made with `per_cable=True`
        ([`jaxcable.controller_init`][]; every array with a leading axis of size n).
    - `cables`: a [`jaxcable.Cable`][] with `length` of shape `(n,)` (the other fields
        `(n,)` or scalars).
    - `state`: the [`jaxcable.states.ControllerState`][] after the previous sample.
    - `time`: time of this sample, s (>= the previous sample's time).
    - `forces`: measured cable forces at this sample, N, shape `(n,)`,
        0 <= force <= `cables.breaking_load`. The force is linear between samples
        and used as measured, with no deadband: the elongations are those of
        [`jaxcable.simulate_force_history`][] on the same history.
    - `throw`: raise at runtime when a cable's result is not successful (default),
        e.g. `RESULTS.strain_beyond_break` for a cable strained beyond its
        `breaking_strain`. With `throw=False` the failures stay in `state.result`,
        one per cable.

    **Returns:**

    `(new_state, elongations)`: the new [`jaxcable.states.ControllerState`][] and each
    cable's predicted elongation, m, shape `(n,)`.

    Concrete (untraced) inputs are validated at the Python boundary, raising
    `ValueError` naming the argument; traced ones are flagged in `state.result`
    (a negative force or a time going backwards), which `throw=True` raises.

    **Example.** Creep-compensated winch lengths for a robot's 8 cables:

    ```python
    import jax
    import jax.numpy as jnp
    import jaxcable as jc

    model = jc.IntegratedModel()
    lengths = jnp.linspace(6.0, 8.0, 8)  # m, current free lengths

    def cables(lengths):  # 6 mm cables; the strain rate is the same for all
        return jc.Cable(lengths, 6e-3, speed=lengths * 2.8e-3, breaking_load=8e3)

    state = jc.controller_init(model, cables(lengths))

    @jax.jit
    def control(state, t, forces, lengths):
        state, elongation = jc.controller_step(model, cables(lengths), state, t, forces)
        return state, lengths - elongation  # commanded winch lengths

    state, command = control(state, 1.0, jnp.full(8, 300.0), lengths)
    ```

    Inside `jax.lax.scan`, make `(state, ...)` the carry and `(t, forces, lengths)` the
    scanned inputs; `jax.grad` of a loss of the commands goes through the whole loop.
    """
    n = _num_cables(cables)
    _check_state(state, n)
    axis = _model_axes(model, n, state.per_cable)
    if _checks.is_concrete(time):
        time = _checks_time(time)
        if _checks.is_concrete(state.packed):
            with jax.ensure_compile_time_eval():  # a concrete state inside a trace
                last = float(np.max(np.asarray(state.cables.time)))
            now = float(np.asarray(time))
            if now < last:
                raise ValueError(
                    f"`time` must not go backwards: {now} s after the previous "
                    f"sample at {last} s."
                )
    if _checks.is_concrete(forces):
        f = np.asarray(forces)
        if f.shape != (n,):
            raise ValueError(f"`forces` must have shape ({n},), got shape {f.shape}.")
        _checks.require_positive("forces", f, allow_zero=True)
        if _checks.is_concrete(cables.breaking_load):
            limit = np.broadcast_to(np.asarray(cables.breaking_load, float), (n,))
            over = f > limit
            if np.any(over):
                i = int(np.flatnonzero(over)[0])
                raise ValueError(
                    f"`forces` exceeds the cable's breaking load: element {i} is "
                    f"{f[i]:g} N > {limit[i]:g} N."
                )
    elif jnp.shape(forces) != (n,):
        raise ValueError(
            f"`forces` must have shape ({n},), got shape {jnp.shape(forces)}."
        )
    cables = _broadcast_cables(cables, n)

    def one(model, cable, cable_state, force):
        new, parts = step(model, cable, cable_state, time, force)
        return new, parts.total * cable.length

    new, elongation = jax.vmap(one, in_axes=(axis, 0, 0, 0))(
        model, cables, state.cables, jnp.asarray(forces)
    )
    if throw:
        result = new.result
        bad = result != RESULTS.successful
        first = jtu.tree_map(lambda v: v[jnp.argmax(bad)], result)
        elongation = first.error_if(elongation, jnp.any(bad))
    return _pack(new, state.per_cable), elongation
