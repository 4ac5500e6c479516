"""The `tensormass` console script: Ctrl-C while the command line is still importing gives the
same one line and exit code 130 as during a run (a command imports sympy, numba and the runtime
when it runs: 2 to 5 s on 2 shared cores; the parser alone, apps.cli, about 0.3 s)."""
from __future__ import annotations

import sys

EXIT_INTERRUPTED = 130      # runtime.base.errors.EXIT_INTERRUPTED, not imported: that is the point


def main(argv=None) -> int:
    try:
        from .apps.cli import main as cli_main
        return cli_main(argv)
    except KeyboardInterrupt:
        print("tensormass: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
