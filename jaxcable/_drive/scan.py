"""The one scan kernel behind every drive: a drive's per-sample step in a `lax.scan`
over its samples (optionally checkpointed in blocks), from the unloaded cable to a
[`jaxcable.Trajectory`][].

A drive (`AbstractDrive`) says what a sample is and how one sample advances the
cable: a time-stamped force (no solve), a force reached at the crosshead's speed (the
time solved) or a time-stamped elongation (the force solved). Everything else, the
scan, the passes of a solved history, the rematerialisation of the backward pass,
padding and the result, is here once.

A drive that solves each sample with jaxcable's `Newton` runs its history in passes
(`run`): a first pass of fixed Newton steps, with no loop and no branch; the robust
pass (Newton's loop, bracket search, bisection) only for a history in which some
sample did not converge in the first; and, only where the simulation is
differentiated, a replay of the history at its solved roots, through which the
derivatives are taken (the implicit function theorem at each root).
"""

import abc
from typing import Generic, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, Bool, Float

from .._cable import Cable
from .._models import AbstractCableModel, StrainParts
from .._results import RESULTS
from .newton import FAST, REPLAY, ROBUST, Newton
from .root_derivatives import loop_tied, split_tangents
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


class Solve(eqx.Module):
    """How a drive's step solves its sample: `how`, `newton.ROBUST`, `FAST` or
    `REPLAY` (see `newton.root_scalar`), and, to replay, the sample's `root` (the
    solved unknown of an earlier pass)."""

    how: str = eqx.field(static=True)
    root: Float[Array, ""] | None = None

    @property
    def known_root(self) -> Float[Array, ""]:
        """`root`, which a `REPLAY` solve is given."""
        assert self.root is not None, "a REPLAY solve is given its root"
        return self.root


_Sample = TypeVar("_Sample", bound=AbstractSample)


class AbstractDrive(eqx.Module, Generic[_Sample]):
    """A way of driving one cable through a history, one sample at a time, each a
    `_Sample` (the drive's `AbstractSample`)."""

    @property
    def two_pass(self) -> bool:
        """Whether the history is solved in passes (`run`): the drive solves its
        samples with jaxcable's `Newton`, which says so (`Newton.two_pass`)."""
        solver = getattr(self, "solver", None)
        return isinstance(solver, Newton) and solver.in_two_passes

    @abc.abstractmethod
    def init(
        self, model: AbstractCableModel, cable: Cable
    ) -> tuple[CableState, _Sample]:
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
        sample: _Sample,
        solve: Solve,
    ) -> tuple[CableState, StrainParts, Float[Array, ""]]:
        """Advance the cable by one sample: the new [`jaxcable.states.CableState`][],
        the [`jaxcable.StrainParts`][] of the sample (both unchanged by a padding
        sample, `sample.mask` False) and the sample's solved unknown (0 where there
        is none), solved as `solve` says."""


class _Output(eqx.Module):
    # What the scan stacks per sample.
    time: Float[Array, ""]
    force: Float[Array, ""]
    strain: Float[Array, ""]
    parts: StrainParts
    root: Float[Array, ""]


# Samples per block of the forward scan, for histories of more than `BLOCK_ABOVE`
# samples (see `_scan`).
BLOCK = 16
BLOCK_ABOVE = 512


def _scan(body, carry: CableState, xs, checkpoint: int | None):
    """`lax.scan` over samples, as a scan over blocks of samples each scanned in turn;
    with `checkpoint`, blocks of that many samples whose body is rematerialised
    (`jax.checkpoint`) in the backward pass.

    Blocks, even without `checkpoint`, for a history of more than `BLOCK_ABOVE`
    samples: a flat scan over a long history writes each sample's outputs into
    arrays of the history's length, which XLA's CPU backend copies on every
    iteration of the loop (the outputs are in its carry); a scan of `BLOCK` samples
    writes into a block, and the outer scan writes whole blocks. A shorter history
    is one flat scan: its copies are small, and a nested scan costs compile time.
    Same operations on the same values, in the same order: results are identical.

    Reverse-mode memory with `checkpoint` grows as (samples / checkpoint) carries
    plus one block of intermediates, instead of every intermediate of every sample:
    choose `checkpoint` near sqrt(samples) for 10^5-10^6-sample histories. The
    history is padded to whole blocks with masked samples, which leave the carry
    unchanged.
    """
    # Reverse mode stores, per sample, only the carry and the solved unknown, and
    # recomputes the rest of the step in the backward pass (no effect on a forward
    # pass). Storing every intermediate of every sample instead (one array of the
    # history's length each, ~100 of them) makes the gradient of a batch memory-bound:
    # measured slower on a large batch (benchmarks/kernel.py).
    body = jax.checkpoint(body, policy=_SAVE_SOLUTION)
    if checkpoint is not None and (
        not isinstance(checkpoint, int)
        or isinstance(checkpoint, bool)
        or checkpoint < 1
    ):
        raise ValueError(f"`checkpoint` must be a positive int, got {checkpoint!r}.")
    samples, roots = xs
    n = jnp.shape(samples.mask)[0]
    if checkpoint is None and n <= BLOCK_ABOVE:
        return jax.lax.scan(body, carry, xs)
    size = BLOCK if checkpoint is None else checkpoint
    blocks = -(-n // size)
    pad = blocks * size - n

    def padded(x, fill):
        return jnp.concatenate([x, jnp.repeat(fill, pad, axis=0)]) if pad else x

    # Padding repeats the last sample, masked.
    mask = padded(samples.mask, jnp.zeros_like(samples.mask[-1:]))
    samples, roots = jtu.tree_map(lambda x: padded(x, x[-1:]), (samples, roots))
    samples = eqx.tree_at(lambda s: s.mask, samples, mask)
    xs = jtu.tree_map(lambda x: x.reshape(blocks, size, *x.shape[1:]), (samples, roots))

    def block(carry, samples_block):
        return jax.lax.scan(body, carry, samples_block)

    if checkpoint is not None:
        block = jax.checkpoint(block)
    final, ys = jax.lax.scan(block, carry, xs)
    ys = jtu.tree_map(lambda y: y.reshape(blocks * size, *y.shape[2:])[:n], ys)
    return final, ys


def _pass(
    drive: AbstractDrive,
    model: AbstractCableModel,
    cable: Cable,
    how: str,
    checkpoint: int | None,
    roots: Float[Array, " samples"] | None = None,
) -> tuple[Trajectory, Float[Array, " samples"]]:
    """One pass of the drive's history, each sample solved as `how` says (`roots`:
    the samples' known unknowns, to replay them): the trajectory and each sample's
    solved unknown."""
    state, samples = drive.init(model, cable)

    def body(state, xs):
        sample, root = xs
        new, parts, solved = drive.step(model, cable, state, sample, Solve(how, root))
        return new, _Output(new.time, new.force, new.strain, parts, solved)

    final, out = _scan(body, state, (samples, roots), checkpoint)
    traj = Trajectory(
        time=out.time,
        force=out.force,
        strain=out.strain,
        elongation=out.strain * cable.length,
        parts=out.parts,
        mask=samples.mask,
        result=final.result,
    )
    return traj, out.root


def _solved_primal(drive, model, cable, checkpoint):
    """The fast pass, then the robust pass where the fast one left a sample
    unconverged: the trajectory and each sample's root.

    The robust pass runs in a loop taken at most once, and only where needed: under
    `vmap` a batch whose histories all converged in the fast pass never runs it (a
    `lax.cond` there would become a select that runs both). Its inputs are tied to
    the loop's counter so that XLA cannot hoist it out of the loop."""
    traj, roots = _pass(drive, model, cable, FAST, checkpoint)
    need = traj.result == RESULTS.newton_failed

    def robust(c):
        passes, _ = c
        d, m, k = loop_tied((drive, model, cable), passes)
        return passes + 1, _pass(d, m, k, ROBUST, checkpoint)

    _, (traj, roots) = jax.lax.while_loop(
        lambda c: need & (c[0] == 0), robust, (jnp.zeros((), jnp.int32), (traj, roots))
    )
    return traj, roots


@eqx.filter_custom_jvp
def _solved(drive, model, cable, *, checkpoint):
    return _solved_primal(drive, model, cable, checkpoint)[0]


@_solved.def_jvp
def _solved_jvp(primals, tangents, *, checkpoint):
    # The solves are not differentiated: the history is replayed at its roots, each
    # root differentiated by the implicit function theorem (`implicit_root`).
    drive, model, cable = primals
    traj, roots = _solved_primal(drive, model, cable, checkpoint)
    roots = jax.lax.stop_gradient(roots)
    diff, rest = split_tangents(tangents, primals)

    def replay(diff):
        drive, model, cable = eqx.combine(diff, rest)
        return _pass(drive, model, cable, REPLAY, checkpoint, roots)[0]

    _, t_traj = jax.jvp(replay, (diff,), (tangents,))
    t_traj = jtu.tree_map(
        lambda x, t: t if eqx.is_inexact_array(x) else None, traj, t_traj
    )
    return traj, t_traj


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
    if drive.two_pass:
        traj = _solved(drive, model, cable, checkpoint=checkpoint)
    else:
        traj = _pass(drive, model, cable, ROBUST, checkpoint)[0]
    if throw:
        traj = traj.result.error_if(traj, traj.result != RESULTS.successful)
    return traj
