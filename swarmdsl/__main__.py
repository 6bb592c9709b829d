"""`python -m swarmdsl` runs the command-line interface."""

from swarmdsl.cli import main

raise SystemExit(main())
