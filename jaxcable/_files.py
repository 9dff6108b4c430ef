"""Writing files so that nothing is lost: every output is written to a temporary file
beside it and renamed over the target in one step, so a write cut short (a full disk,
a killed process) leaves the old content, never a truncated file."""

import contextlib
import os
import pathlib
import tempfile
from collections.abc import Iterator


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[pathlib.Path]:
    """A temporary path beside `path` to write to; renamed over `path` on success.

    **Arguments:**

    - `path`: the file to write.

    **Yields:**

    The temporary path (same folder, so the rename is atomic). On an exception the
    temporary file is removed and `path` is left as it was.

    **Raises:**

    `OSError` naming `path` when its folder cannot be written.
    """
    target = pathlib.Path(path)
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}.", suffix=".tmp", dir=target.parent or "."
        )
    except OSError as e:
        raise OSError(e.errno, f"cannot write {target}: {e.strerror}", str(target))
    os.close(fd)
    tmp_path = pathlib.Path(tmp)
    # mkstemp makes the file private (0600); give it the mode a plain open() would
    # (the old file's, else 0666 less the umask), so the rename changes no permission.
    try:
        mode = target.stat().st_mode & 0o777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    os.chmod(tmp_path, mode)
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write `text` (UTF-8, newlines as given) to `path` atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
