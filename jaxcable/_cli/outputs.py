"""The files a command writes: refused when one of them is one of its inputs, said in
the command's log when one replaces an existing file, and written atomically with an
error that names the option and the file."""

import contextlib
import os
import pathlib
import sys
from collections.abc import Iterable, Iterator, Sequence
from typing import TextIO

from .._files import atomic_path
from .common import CliError


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether the paths `a` and `b` name the same file (links and `..` resolved)."""
    try:
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
    except OSError:
        pass
    return pathlib.Path(a).resolve() == pathlib.Path(b).resolve()


def refuse_inputs(
    outputs: Sequence[tuple[str, str | os.PathLike]],
    inputs: Sequence[tuple[str, str | os.PathLike]],
) -> None:
    """Fail unless every output is a file of its own: neither an input nor another
    output, nor an existing folder.

    **Arguments:**

    - `outputs`: (option, path) of every file the command will write.
    - `inputs`: (what, path) of every file it reads (what: an option or `DATA.csv`).
    """
    for k, (option, path) in enumerate(outputs):
        if os.path.isdir(path):
            raise CliError(f"{option} {path}: is a folder, not a file.")
        for what, source in inputs:
            if same_file(path, source):
                raise CliError(
                    f"{option} {path}: is the input {what} {source}; writing it would "
                    "replace the input. Choose another file."
                )
        for other_option, other in outputs[:k]:
            if same_file(path, other):
                raise CliError(
                    f"{option} {path}: is also written as {other_option} {other}. "
                    "Choose another file."
                )


def say_replacing(
    paths: Iterable[str | os.PathLike], option: str, log: TextIO | None = None
) -> None:
    """One line naming the files of `paths` that exist (about to be replaced), if
    any, on `log` (default stdout): the command's log, beside its "wrote" lines; stderr
    is kept for the one error line, and `diagnose --json` logs to stderr so that its
    stdout stays one JSON object."""
    existing = [str(p) for p in paths if os.path.isfile(p)]
    if len(existing) > 5:
        existing = [f"{len(existing)} files ({existing[0]}, ...)"]
    if existing:
        print(f"replacing {', '.join(existing)} ({option})", file=log or sys.stdout)


@contextlib.contextmanager
def write_errors(option: str, path: str | os.PathLike) -> Iterator[None]:
    """Around the writing of `path` (a file, or a folder of files): an `OSError`
    becomes an error naming `option`, `path` and the file that could not be written."""
    try:
        yield
    except OSError as e:
        # The reason only ("Permission denied"), and the file unless it is `path`
        # itself or the temporary file beside it.
        reason = str(e.strerror or e).rsplit(": ", 1)[-1]
        name = "" if e.filename is None else pathlib.Path(e.filename).name
        inside = name and name != pathlib.Path(path).name and not name.endswith(".tmp")
        where = f" {e.filename}" if inside else ""
        raise CliError(f"{option} {path}: cannot write{where}: {reason}.") from None


@contextlib.contextmanager
def writing(option: str, path: str | os.PathLike) -> Iterator[pathlib.Path]:
    """A temporary path to write `path` to, renamed over it on success (see
    `jaxcable._files.atomic_path`); errors as in `write_errors`."""
    with write_errors(option, path), atomic_path(path) as tmp:
        yield tmp


def report_files(folder, names) -> list[tuple[str, pathlib.Path]]:
    """(option, path) of the files of a `--report` folder; fails when the folder is
    an existing file."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise CliError(f"--report {folder}: is a file, not a folder.")
    return [("--report", pathlib.Path(folder) / name) for name in names]
