"""The `jaxcable` command line as a function, for scripts and notebooks that run its
commands in-process: `jaxcable.cli.main(["fit", "data.csv", "--out", "p.json"])`
returns the exit status the console script would."""

from ._cli import main as main
