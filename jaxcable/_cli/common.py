"""What every command of the command line shares: the error it reports, the progress
switch and the output folders."""

import pathlib
import sys

from .._progress import TextProgressMeter


PROG = "jaxcable"


class CliError(Exception):
    """An error to report as one line on stderr, with an exit status.

    **Arguments:**

    - `message`: what is wrong and where (the file, line and column, or the option).
    - `status`: the exit status: 2 for bad input (the default), 1 when a simulation
        or fit fails.
    """

    def __init__(self, message: str, status: int = 2):
        super().__init__(message)
        self.status = status


def one_line(message) -> str:
    """`message` with every run of whitespace (newlines included) made one space."""
    return " ".join(str(message).split())


def progress_meter(args, log=None) -> TextProgressMeter:
    """The progress meter of a command run with `args`: bars on stderr when it is a
    terminal and `--quiet` is not given, and news on `log` (None: no news)."""
    # Carriage-return bars only on a terminal: logs and pipes get none.
    return TextProgressMeter(show_bar=not args.quiet and sys.stderr.isatty(), log=log)


def require_folder_of(path: str, option: str) -> None:
    """Fail, naming `option`, unless the folder that is to hold `path` exists."""
    parent = pathlib.Path(path).resolve().parent
    if not parent.is_dir():
        raise CliError(f"{option} {path}: folder {parent} does not exist.")


def make_folder(path: pathlib.Path, option: str) -> None:
    """Create the folder `path` (and its parents); fail naming `option`."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CliError(
            f"{option} {path}: cannot create the folder: {e.strerror}."
        ) from None
