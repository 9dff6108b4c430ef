"""The one scan kernel behind every drive: a drive's per-sample step in a `lax.scan`
over its samples (optionally checkpointed in blocks), from the unloaded cable to a
[`jaxcable.Trajectory`][].

A drive (`AbstractDrive`) says what a sample is and how one sample advances the
cable: a time-stamped force (no solve), a force reached at the crosshead's speed (the
time solved) or a time-stamped elongation (the force solved). Everything else, the
scan, the rematerialisation of the backward pass, padding and the result, is here
once."""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, Bool

from .._cable import Cable
from .._models import AbstractCableModel, StrainParts
from .._results import RESULTS
from .state import CableState, Trajectory


# The name under which the drives mark the solved unknown of each sample (the loading
# time of a rate-driven test, the force of an elongation history), and the
# rematerialisation policy that keeps it, so that the backward pass does not redo the
# Newton solve.
SOLUTION = "jaxcable_solution"
_SAVE_SOLUTION = jax.checkpoint_policies.save_only_these_names(SOLUTION)


class AbstractSample(eqx.Module):
    """One sample of a drive's input history (a leading `samples` axis outside the
    scan). Every sample carries `mask`: False for padding, which the kernel also uses
    to pad a checkpointed history to whole blocks."""

    mask: eqx.AbstractVar[Bool[Array, "*samples"]]


class AbstractDrive(eqx.Module):
    """A way of driving one cable through a history, one sample at a time."""

    @abc.abstractmethod
    def init(
        self, model: AbstractCableModel, cable: Cable
    ) -> tuple[CableState, AbstractSample]:
        """The state of the unloaded cable before the first sample, and the samples
        to scan (each field with a leading `samples` axis).

        Called inside the kernel's `jit`, so building the samples here costs no
        dispatch."""

    @abc.abstractmethod
    def step(
        self,
        model: AbstractCableModel,
        cable: Cable,
        state: CableState,
        sample: AbstractSample,
    ) -> tuple[CableState, StrainParts]:
        """Advance the cable by one sample: the new [`jaxcable.states.CableState`][] and the
        [`jaxcable.StrainParts`][] of the sample (both unchanged by a padding sample,
        `sample.mask` False)."""


class _Output(eqx.Module):
    # What the scan stacks per sample.
    state: CableState
    parts: StrainParts


def _scan(body, carry: CableState, samples: AbstractSample, checkpoint: int | None):
    """`lax.scan` over samples; with `checkpoint`, a scan over blocks of that many
    samples whose body is rematerialised (`jax.checkpoint`) in the backward pass.

    Reverse-mode memory then grows as (samples / checkpoint) carries plus one block of
    intermediates, instead of every intermediate of every sample: choose
    `checkpoint` near sqrt(samples) for 10^5-10^6-sample histories. The history is
    padded to whole blocks with masked samples, which leave the carry unchanged.
    """
    # Reverse mode stores, per sample, only the carry and the solved unknown, and
    # recomputes the rest of the step in the backward pass (no effect on a forward
    # pass). Storing every intermediate of every sample instead (one array of the
    # history's length each, ~100 of them) makes the gradient of a batch memory-bound:
    # measured slower on a large batch (benchmarks/kernel.py).
    body = jax.checkpoint(body, policy=_SAVE_SOLUTION)
    if checkpoint is None:
        return jax.lax.scan(body, carry, samples)
    if not isinstance(checkpoint, int) or checkpoint < 1:
        raise ValueError(f"`checkpoint` must be a positive int, got {checkpoint!r}.")
    n = jnp.shape(samples.mask)[0]
    blocks = -(-n // checkpoint)
    pad = blocks * checkpoint - n

    def padded(x, fill):
        return jnp.concatenate([x, jnp.repeat(fill, pad, axis=0)]) if pad else x

    # Padding repeats the last sample, masked.
    mask = padded(samples.mask, jnp.zeros_like(samples.mask[-1:]))
    samples = jtu.tree_map(lambda x: padded(x, x[-1:]), samples)
    samples = eqx.tree_at(lambda s: s.mask, samples, mask)
    samples = jtu.tree_map(
        lambda x: x.reshape(blocks, checkpoint, *x.shape[1:]), samples
    )

    @jax.checkpoint
    def block(carry, samples_block):
        return jax.lax.scan(body, carry, samples_block)

    final, ys = jax.lax.scan(block, carry, samples)
    ys = jtu.tree_map(lambda y: y.reshape(blocks * checkpoint, *y.shape[2:])[:n], ys)
    return final, ys


@eqx.filter_jit
def run(
    drive: AbstractDrive,
    model: AbstractCableModel,
    cable: Cable,
    throw: bool,
    checkpoint: int | None,
) -> Trajectory:
    """Simulate one cable through a drive's history.

    **Arguments:**

    - `drive`: the `AbstractDrive` holding the history.
    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][] (one cable).
    - `throw`: raise on failure; otherwise the failure is in `Trajectory.result`.
    - `checkpoint`: the block length of a checkpointed scan, or None.

    **Returns:**

    A [`jaxcable.Trajectory`][].
    """
    state, samples = drive.init(model, cable)

    def body(state, sample):
        new, parts = drive.step(model, cable, state, sample)
        return new, _Output(new, parts)

    final, out = _scan(body, state, samples, checkpoint)
    traj = Trajectory(
        time=out.state.time,
        force=out.state.force,
        strain=out.state.strain,
        elongation=out.state.strain * cable.length,
        parts=out.parts,
        mask=samples.mask,
        result=final.result,
    )
    if throw:
        traj = final.result.error_if(traj, final.result != RESULTS.successful)
    return traj
