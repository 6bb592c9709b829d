"""`python -m swarmdsl` runs the command-line interface.

The guard matters: a sweep's worker processes (spawned, or a Dask LocalCluster's
nannies) import the main module again, and must not start a second command.
"""

from swarmdsl.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
