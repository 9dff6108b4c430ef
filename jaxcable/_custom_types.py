from typing import TypeAlias

from jaxtyping import Array, ArrayLike, Bool, Float, Int


Scalar: TypeAlias = Float[Array, ""]
ScalarLike: TypeAlias = float | Float[ArrayLike, ""]
Samples: TypeAlias = Float[Array, " samples"]
BoolSamples: TypeAlias = Bool[Array, " samples"]
IntSamples: TypeAlias = Int[Array, " samples"]
