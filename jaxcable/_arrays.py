"""How a Module's array field holds a number: one converter for every parameter and
input field of jaxcable's Modules (models, cables, protocols, distributions).

`jnp.asarray(0.3)` is *weakly typed*: its dtype defers to the other operand in
arithmetic, and `jit` compiles a weakly typed argument into a different program
(with other converts) than a strongly typed one of the same dtype. A model built from
Python numbers (the defaults) would then compile every kernel once, and the same
model with fitted values (strongly typed arrays) once again: measured on the
diagnosis's held-out simulation, two programs where one serves.
`field_array` gives every field a definite dtype, so that both share one program.
"""

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike


def field_array(x: ArrayLike) -> Array:
    """`x` as a jax array with a definite (not weak) dtype.

    **Arguments:**

    - `x`: a number, a NumPy array or a jax array (a tracer too, inside `jit`,
        `vmap` or `grad`).

    **Returns:**

    A jax array of `x`'s dtype: a Python float becomes jax's default float
    (float64 under `jax_enable_x64`, else float32), a jax array keeps its dtype and
    only loses a weak type. Python numbers and NumPy arrays are converted on the host,
    so that building a model dispatches no device computation.
    """
    if isinstance(x, jax.Array):
        return jnp.asarray(x, dtype=x.dtype) if x.weak_type else x
    # NumPy arrays are never weakly typed; jax canonicalises their dtype.
    return jnp.asarray(np.asarray(x))


def optional_field_array(x: ArrayLike | None) -> Array | None:
    """[`field_array`][] of `x`, or None."""
    return None if x is None else field_array(x)
