"""`jaxcable cache`: where the compiled kernels are kept, how big, and clearing them."""

from .._cache import (
    NO_CACHE_ENV,
    cache_disabled,
    cache_size,
    clear_compilation_cache,
    default_cache_dir,
)


def cache_command(args) -> int:
    """Print the cache directory and its size; with `--clear`, delete it."""
    path = default_cache_dir()
    if args.clear:
        freed = clear_compilation_cache(path)
        print(f"Cleared {path} ({freed / 1e6:.1f} MB).")
        return 0
    files, size = cache_size(path)
    state = f"off ({NO_CACHE_ENV} is set)" if cache_disabled() else "on"
    print(f"Compilation cache: {state}")
    print(f"Directory: {path}")
    print(f"Entries: {files} files, {size / 1e6:.1f} MB")
    return 0
