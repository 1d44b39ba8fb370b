"""The ``lidarsim`` command that ``pip install`` puts on the PATH: the same command line as
the Rust binary, run by the compiled core."""

import signal
import sys

from . import _lidarsim


def _leave(_signum: int, _frame: object) -> None:
    # The command has said what it kept; end as the Rust binary does (1, a run that did not
    # finish), without a traceback on top.
    raise SystemExit(1)


def main() -> None:
    # `run` stops at its next part on Ctrl-C and returns 1 itself; the interpreter, which
    # sees the signal too, must then leave quietly rather than raise KeyboardInterrupt
    signal.signal(signal.SIGINT, _leave)
    sys.exit(_lidarsim.cli_main(["lidarsim", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
