"""The persistent compilation cache: XLA programs kept on disk between processes.

Compiling the scan kernels takes seconds; solving takes a fraction of that. JAX can
keep compiled programs on disk (its persistent compilation cache), so that a second
process with the same shapes loads them instead of compiling. The library never turns
it on by itself (importing jaxcable leaves `jax.config` alone); the command line turns
it on for every command, and a script or notebook can with
[`jaxcable.enable_compilation_cache`][].

The compilation cache saves compiling, not tracing and lowering the program, which
is about as long for the fit kernel: the command line also keeps each fit kernel it
runs as an exported program (`jax.export`) in `exported/` inside the same directory
([`exported_programs_dir`][]), turned off and cleared with the rest.
"""

import os
import pathlib
import shutil

import jax


# Where the cache lives unless told otherwise, and the switch that turns the command
# line's cache off.
CACHE_DIR_ENV = "JAXCABLE_CACHE_DIR"
NO_CACHE_ENV = "JAXCABLE_NO_CACHE"


def default_cache_dir() -> pathlib.Path:
    """The per-user cache directory: `$JAXCABLE_CACHE_DIR`, else
    `$XDG_CACHE_HOME/jaxcable/jax`, else `~/.cache/jaxcable/jax`."""
    explicit = os.environ.get(CACHE_DIR_ENV)
    if explicit:
        return pathlib.Path(explicit).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or pathlib.Path.home() / ".cache"
    return pathlib.Path(base) / "jaxcable" / "jax"


def exported_programs_dir() -> pathlib.Path | None:
    """Where the command line keeps its exported fit programs (traced and lowered,
    see `jaxcable._fit.exported`): `exported/` in `default_cache_dir`, cleared
    with it; `None` when `$JAXCABLE_NO_CACHE` turns the cache off."""
    if cache_disabled():
        return None
    return default_cache_dir() / "exported"


def cache_disabled() -> bool:
    """True when `$JAXCABLE_NO_CACHE` is set to anything but `""` or `"0"`."""
    return os.environ.get(NO_CACHE_ENV, "") not in ("", "0")


def enable_compilation_cache(
    directory: str | os.PathLike | None = None,
) -> pathlib.Path | None:
    """Keep compiled programs on disk, so that later processes load them.

    Changes `jax.config` (the cache directory, and caching every program however fast
    it compiled: jaxcable's many small kernels add up). A cache directory already set
    in `jax.config` (e.g. by `JAX_COMPILATION_CACHE_DIR`) is kept.

    **Arguments:**

    - `directory`: where to keep them (default `default_cache_dir`: per user).

    **Returns:**

    The directory in use, or `None` when `$JAXCABLE_NO_CACHE` turns the cache off
    and no `directory` is given.
    """
    # jax's Config sets its options as attributes at run time.
    current = jax.config.jax_compilation_cache_dir  # pyright: ignore[reportAttributeAccessIssue]
    if directory is None:
        if current:
            return pathlib.Path(current)
        if cache_disabled():
            return None
    path = pathlib.Path(directory) if directory is not None else default_cache_dir()
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return path


def cache_size(directory: str | os.PathLike | None = None) -> tuple[int, int]:
    """(number of files, bytes) in the cache directory (default: the per-user one)."""
    path = pathlib.Path(directory) if directory is not None else default_cache_dir()
    if not path.is_dir():
        return 0, 0
    files = [p for p in path.rglob("*") if p.is_file()]
    return len(files), sum(p.stat().st_size for p in files)


def clear_compilation_cache(directory: str | os.PathLike | None = None) -> int:
    """Delete the cache directory (default: the per-user one); return the bytes freed.

    Refuses a directory that does not look like a compilation cache (a file in it
    that is not a cache entry), so that a mistyped path deletes nothing.
    """
    path = pathlib.Path(directory) if directory is not None else default_cache_dir()
    if not path.is_dir():
        return 0
    for p in path.rglob("*"):
        if p.is_file() and not p.name.endswith(("-cache", "-atime")):
            raise ValueError(
                f"{path}: {p.name} is not a compilation-cache entry; not deleting."
            )
    _, size = cache_size(path)
    shutil.rmtree(path)
    return size
