"""What every command of the command line shares: the error it reports, the progress
switch and the output folders."""

import contextlib
import pathlib
import sys
from collections.abc import Iterator

import jax

from .._problem import LeastSquares
from .._progress import TextProgressMeter
from .._uncertainty import NUTS


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


@contextlib.contextmanager
def refused(prefix: str) -> Iterator[None]:
    """Within it, a `ValueError` (the library refusing a value, naming it) is the
    command line's error: `prefix: message`, exit status 2."""
    try:
        yield
    except ValueError as e:
        raise CliError(f"{prefix}: {e}") from None


def one_line(message) -> str:
    """`message` with every run of whitespace (newlines included) made one space."""
    return " ".join(str(message).split())


def progress_meter(quiet: bool, log=None) -> TextProgressMeter:
    """The progress meter of a command: bars on stderr when it is a terminal and
    `--quiet` (`quiet`) is not given, and news on `log` (None: no news)."""
    # Carriage-return bars only on a terminal: logs and pipes get none.
    return TextProgressMeter(show_bar=not quiet and sys.stderr.isatty(), log=log)


def add_choice(group, flag: str, choices: tuple[str, ...], help: str) -> None:
    """Add the option `flag` to the argparse `group`: one of `choices`, the first
    by default."""
    group.add_argument(flag, choices=choices, default=choices[0], help=help)


def least_squares(args) -> LeastSquares:
    """The least-squares method the solver flags of the parsed command line `args`
    give: `--starts`, `--max-steps`, and `--seed` for the start perturbations."""
    return LeastSquares(
        max_steps=args.max_steps, multistart=args.starts, key=jax.random.key(args.seed)
    )


def nuts(args) -> NUTS:
    """The sampler the posterior flags of the parsed command line `args` give:
    `--posterior` draws per chain, `--chains` chains, as many warm-up steps (at
    least 200), and the key of `--seed`."""
    n = args.posterior
    return NUTS(
        num_samples=n,
        num_chains=args.chains,
        num_warmup=max(n, 200),
        key=jax.random.key(args.seed),
    )


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
