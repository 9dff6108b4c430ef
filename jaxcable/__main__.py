"""`python -m jaxcable`: the same as the `jaxcable` command."""

from ._cli import main


raise SystemExit(main())
