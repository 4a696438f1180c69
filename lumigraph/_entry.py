"""The ``lumigraph`` console script's entry point: as little as possible is
imported before Ctrl-C is handled, so an interrupt while the libraries load
ends with one line and status 130, not a traceback."""

import signal
import sys

_interrupted = False


def _on_sigint(signum, frame):
    # Remember the Ctrl-C: one landing inside a C extension's import can
    # surface as an unrelated exception (a TypeError, a RuntimeError) that no
    # longer carries the KeyboardInterrupt.
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


def _after_commit():
    # the command had committed its result when the Ctrl-C landed on its way
    # out: it ends with its own status (nothing is imported here that was not
    # already); None when it had not
    commandline = sys.modules.get("lumigraph.capture.commandline")
    return None if commandline is None else commandline.committed_status()


def main() -> int:
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_sigint)
    try:
        from lumigraph.command import main as command_main

        return command_main()
    except KeyboardInterrupt:
        if (status := _after_commit()) is not None:
            return status
        sys.stderr.write("error: interrupted; nothing was written\n")
        return 130
    except Exception as e:
        from lumigraph.capture.errors import caused_by_interrupt

        if not (_interrupted or caused_by_interrupt(e)):
            raise
        if (status := _after_commit()) is not None:
            return status
        sys.stderr.write("error: interrupted; nothing was written\n")
        return 130
