"""The `jaxcable` command line: `jaxcable simulate`, `fit`, `diagnose`, `design` and `demo`.

Errors in the user's input (files, arguments) exit with status 2 and one line on
stderr saying what is wrong and where; a simulation or fit that fails exits with
status 1.

Each command's entry (`fit_command`, `diagnose_command`, ...) turns the parsed flags
once into a frozen request of typed values: the model asked for, the data files with
their `jaxcable.ReadOptions`, the library's method values (`jaxcable.LeastSquares`,
`jaxcable.NUTS`, `jaxcable.CandidateSearch`) and the output paths. The functions
below it take these values; no argparse namespace travels further.
"""

import gc
import sys
from collections.abc import Sequence

import jax

from .._cache import enable_compilation_cache
from .common import PROG, CliError, one_line
from .parser import build_parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the `jaxcable` command line.

    **Arguments:**

    - `argv`: the arguments after the program name (default: `sys.argv[1:]`).

    **Returns:**

    The exit status: 0 on success, 2 for bad input (one line on stderr naming the
    file, line and column, or the option), 1 when a simulation or fit fails.
    """
    try:
        args = build_parser().parse_args(argv)
        if args.command != "cache":
            # Compiling is most of a command's time: the next run loads the programs.
            enable_compilation_cache()
        # The command line writes files, so its precision must not depend on the
        # caller's jax config: float32 Newton solves of rate-driven tests do not
        # converge at the default tolerances. Scoped; jax.config is left as it was.
        with jax.enable_x64(True):
            return args.run(args)
    except SystemExit as e:  # --help and --version
        return e.code if isinstance(e.code, int) else 0
    except CliError as e:
        _report(e)
        return e.status
    # The library's readers (CSV, protocol and parameter files) raise ValueError
    # naming the file, line and column: bad input, reported as it is.
    except ValueError as e:
        _report(e)
        return 2
    except OSError as e:
        where = e.filename if e.filename is not None else "file"
        _report(f"{where}: {e.strerror or e}.")
        return 2


def entry() -> None:
    """The `jaxcable` console script and `python -m jaxcable`: [`main`][] on the
    process's arguments, exiting with its status.

    First it freezes the objects that importing jax and jaxcable created (modules,
    classes, the compiler's bindings: they live as long as the process), so that the
    cyclic garbage collector, run by the allocations of tracing and loading
    programs, no longer rescans them (benchmarks/README.md has the gain on a warm
    `jaxcable fit`). Only here, not in `main`, which a test or a script may call
    many times in one process.

    XLA compiles the scans' loops as single CPU kernels, as `import jaxcable` set up
    ([`jaxcable.enable_cpu_loop_kernels`][]; `$JAXCABLE_NO_LOOP_KERNELS` leaves
    XLA's default).
    """
    gc.freeze()
    raise SystemExit(main())


def _report(message) -> None:
    print(f"{PROG}: error: {one_line(message)}", file=sys.stderr)
