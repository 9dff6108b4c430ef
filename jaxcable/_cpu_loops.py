"""XLA's CPU option that compiles a small while loop as one kernel, for the scans.

On a CPU, XLA runs a program as a sequence of kernels (its "thunks"), one for each
fused operation, and a `lax.scan` runs its body's kernels one after the other on
every iteration, at roughly 50 ns each. A rate-driven sample of jaxcable's kernel is
about 100 of them (the model's step, Newton's method and its loops), so one cable's
simulation is that dispatch, not arithmetic. XLA can instead compile a while loop
whose buffers are small into one kernel (`xla_cpu_small_while_loop_byte_threshold`,
1024 bytes by default): the whole scan of one cable then runs as compiled code,
several times faster for one cable, and it compiles faster too
(`benchmarks/peer_numba.py`, `benchmarks/kernel.py`; results in benchmarks/README.md).

The option is an XLA flag (`XLA_FLAGS`), read once, when JAX starts its CPU backend
(the first computation of a process); it cannot be scoped to one program. So
`import jaxcable` sets it (`enable_at_import`), which computes nothing, unless
`$JAXCABLE_NO_LOOP_KERNELS` says no or `XLA_FLAGS` already sets the threshold; where
JAX has already computed before jaxcable's import, it warns once that the option
cannot take effect in this process. Every other XLA flag is kept as it was.
"""

import os
import warnings

from ._checks import require_int


# The flag, as XLA's CPU backend reads it from `--xla_backend_extra_options`.
_OPTION = "xla_cpu_small_while_loop_byte_threshold"
_EXTRA = "--xla_backend_extra_options="
# 16 MiB: the scan of one cable (its stacked outputs are the loop's largest
# buffers: 2000 samples take about 0.1 MB), and the Newton loops of a batch of
# 1024 cables, which need between 2 and 4 MB (below that a 1024-cable forward
# keeps its speed). At 16 MB the whole scan of those 1024 cables
# (benchmarks/kernel.py's forward, and its gradient's two scans) is one
# single-threaded kernel as well, which was faster than XLA's spreading of each
# small kernel over the cores, on 2 and on 16 cores (thresholds and timings:
# benchmarks/README.md).
DEFAULT_LOOP_KERNEL_BYTES = 1 << 24
# The switch that leaves XLA's default (at import and on the command line).
NO_LOOP_KERNELS_ENV = "JAXCABLE_NO_LOOP_KERNELS"


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):
        # A jax without this (private) query: asking for the devices would start
        # the backend, so assume it has not; the flag then at worst does nothing.
        return False


def with_loop_kernel_option(flags: str, byte_threshold: int) -> str:
    """`flags` (an `XLA_FLAGS` value) with the loop threshold added, merged into an
    `--xla_backend_extra_options` already there; a threshold already set is kept."""
    entry = f"{_OPTION}={byte_threshold}"
    words = flags.split()
    for i, word in enumerate(words):
        if word.startswith(_EXTRA):
            options = word[len(_EXTRA) :]
            if _OPTION in options:
                return flags
            words[i] = _EXTRA + (f"{options},{entry}" if options else entry)
            return " ".join(words)
    return " ".join(words + [_EXTRA + entry])


def enable_cpu_loop_kernels(byte_threshold: int = DEFAULT_LOOP_KERNEL_BYTES) -> str:
    """Let XLA compile each while loop (a scan) whose buffers fit in `byte_threshold`
    bytes as one CPU kernel, for the rest of this process.

    Adds `--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=N` to
    the `XLA_FLAGS` environment variable, which JAX reads when it starts its CPU
    backend: call it before the first computation. `import jaxcable` already calls
    it with the default threshold (unless `$JAXCABLE_NO_LOOP_KERNELS` is set); a
    call of yours replaces that default, while a threshold that `XLA_FLAGS` set
    before the import is kept. Results are the same
    computation, compiled differently: in float64 within rounding of XLA's default
    (tested), on other backends nothing changes.

    **Arguments:**

    - `byte_threshold`: the largest total size, in bytes, of a loop's buffers for it
        to become one kernel (default 16 MiB: one cable's scan, and the Newton
        loops of up to a few thousand cables).

    **Returns:**

    The `XLA_FLAGS` now in effect.

    **Raises:**

    `RuntimeError` when JAX's backend has already started (the flag would do
    nothing); `TypeError` for a threshold that is not an integer and `ValueError`
    for one below 1 (bytes).
    """
    require_int("byte_threshold", byte_threshold, low=1)
    if _backend_started():
        raise RuntimeError(
            "enable_cpu_loop_kernels: JAX's backend has already started, so XLA_FLAGS "
            "are read already; call it before the first computation of the process."
        )
    flags = os.environ.get("XLA_FLAGS", "")
    if _import_flags is not None and flags == _import_flags[1]:
        # The import's default, not a choice of the user's: replaced.
        flags = _import_flags[0]
    flags = with_loop_kernel_option(flags, byte_threshold)
    os.environ["XLA_FLAGS"] = flags
    return flags


# `XLA_FLAGS` before and after `enable_at_import` set them, where it did.
_import_flags: tuple[str, str] | None = None


def loop_kernels_disabled() -> bool:
    """True when `$JAXCABLE_NO_LOOP_KERNELS` is set to anything but `""` or `"0"`."""
    return os.environ.get(NO_LOOP_KERNELS_ENV, "") not in ("", "0")


class LoopKernelWarning(UserWarning):
    """`import jaxcable` came after JAX's first computation on the CPU, so the CPU loop
    kernels it enables (see [`jaxcable.enable_cpu_loop_kernels`][]) cannot take effect
    in this process: the simulations are correct, several times slower for one
    cable. Import jaxcable before computing, or set `$JAXCABLE_NO_LOOP_KERNELS=1` to
    keep XLA's default without the warning."""


def _started_on_cpu() -> bool:
    # Only asked once the backends have started, so this starts nothing.
    import jax

    return jax.default_backend() == "cpu"


def enable_at_import() -> bool:
    """What `import jaxcable` does: [`enable_cpu_loop_kernels`][] with its default,
    unless `$JAXCABLE_NO_LOOP_KERNELS` is set or `XLA_FLAGS` already sets the
    threshold; a `LoopKernelWarning` where JAX's CPU backend has already started.
    Whether the option was set now."""
    if loop_kernels_disabled() or _OPTION in os.environ.get("XLA_FLAGS", ""):
        return False
    if _backend_started():
        if _started_on_cpu():
            warnings.warn(
                "jaxcable was imported after JAX's first computation, so its CPU loop "
                "kernels (XLA_FLAGS, read when JAX starts) cannot take effect in this "
                "process: the simulations run several times slower. Import jaxcable "
                f"before computing, or set {NO_LOOP_KERNELS_ENV}=1 to silence this.",
                LoopKernelWarning,
                stacklevel=2,
            )
        return False
    global _import_flags
    before = os.environ.get("XLA_FLAGS", "")
    _import_flags = (before, enable_cpu_loop_kernels())
    return True
