"""The ``lumigraph`` console script's entry point: as little as possible is
imported before Ctrl-C is handled, so an interrupt while the libraries load
ends with one line and status 130, not a traceback."""

import sys


def main() -> int:
    try:
        from lumigraph.command import main as command_main

        return command_main()
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted; nothing was written\n")
        return 130
