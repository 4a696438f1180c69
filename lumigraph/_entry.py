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
    except Exception as e:
        # A Ctrl-C inside an import can surface wrapped (e.g. the RuntimeError
        # of a dataclass's __set_name__): still the user's interrupt.
        from lumigraph.capture.errors import caused_by_interrupt

        if not caused_by_interrupt(e):
            raise
        sys.stderr.write("error: interrupted; nothing was written\n")
        return 130
