"""The ``lidarsim`` command that ``pip install`` puts on the PATH: the same command line as
the Rust binary, run by the compiled core."""

import sys

from . import _lidarsim


def main() -> None:
    sys.exit(_lidarsim.cli_main(["lidarsim", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
