"""A scan over a long record in blocks: each block's samples scanned in turn.

XLA's CPU backend compiles a while loop whose buffers are small as one kernel
(`jaxcable.enable_cpu_loop_kernels`, 16 MiB); a `lax.scan` over a whole record carries
the record's inputs and outputs in its loop, which for a long record (a robot's day:
8.6 million samples) is far beyond that, so each sample would dispatch its many small
kernels. A scan over blocks keeps the inner loop, where the time goes, within the
limit. The same operations on the same values in the same order: the results are
those of the flat scan.
"""

import jax
import jax.numpy as jnp


# Samples per block, and the length above which a record is scanned in blocks.
BLOCK = 4096


def blocked_scan(body, init, xs: tuple, off: tuple[int, ...]):
    """`lax.scan(body, init, xs)` over blocks of `BLOCK` samples.

    **Arguments:**

    - `body`, `init`: as `lax.scan`'s.
    - `xs`: a tuple of arrays with a leading samples axis.
    - `off`: the positions in `xs` of the masks and weights that a padding sample
        sets to False or 0, so that it leaves the carry unchanged (the record is
        padded to whole blocks with its last sample, so masked).

    **Returns:**

    `(final, ys)`, as `lax.scan`'s (`ys` of the record's length).
    """
    n = xs[0].shape[0]
    if n <= BLOCK:
        return jax.lax.scan(body, init, xs)
    blocks = -(-n // BLOCK)
    pad = blocks * BLOCK - n

    def padded(k, x):
        fill = jnp.zeros_like(x[-1:]) if k in off else x[-1:]
        return jnp.concatenate([x, jnp.repeat(fill, pad, axis=0)])

    xs = tuple(
        padded(k, x).reshape(blocks, BLOCK, *x.shape[1:]) for k, x in enumerate(xs)
    )
    final, ys = jax.lax.scan(lambda c, b: jax.lax.scan(body, c, b), init, xs)
    ys = jax.tree_util.tree_map(
        lambda y: y.reshape(blocks * BLOCK, *y.shape[2:])[:n], ys
    )
    return final, ys
