"""The ``lumigraph`` command: one subcommand per stage.

This is the shell, the top floor (see ARCHITECTURE.md): ``lumigraph <stage> …``
imports only the chosen stage's ``cli`` module, so a ``make`` step pays for
the libraries it uses and no more. Each stage's ``cli`` module provides
``main(argv=None, prog=...) -> int`` built with
:func:`lumigraph.capture.commandline.make_parser` and
:func:`lumigraph.capture.commandline.run`.

Examples
--------
>>> main(["--version"])  # doctest: +ELLIPSIS
lumigraph ...
0
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence

from lumigraph.capture.commandline import EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE
from lumigraph.capture.registry import Method, Registry

# stage name -> the stage's main() and its one-line summary, in the one
# registry shape (lumigraph.capture.registry). Targets are imported on use, so
# `lumigraph --help` imports nothing heavy.
STAGES = Registry("stage", [
    Method("render", "lumigraph.capture.cli:main", "render synthetic scenes with exact ground truth"),
    Method("calib", "lumigraph.calib.cli:main",
           "camera calibration, stereo rigs, undistortion, rectification"),
    Method("hdr", "lumigraph.hdr.cli:main",
           "camera response, radiance merge, alignment, tone mapping, HDR files"),
    Method("flow", "lumigraph.stereo.flow_cli:main", "optical flow and Sand-Teller video matching"),
    Method("stereo", "lumigraph.stereo.cli:main", "block-matching stereo, triangulation, depth, SfM"),
    Method("lightfield", "lumigraph.lightfield.cli:main",
           "light fields: import, lenslet decode, refocus, render"),
    Method("separate", "lumigraph.separation.cli:main",
           "direct/global separation with projected patterns"),
    Method("bench", "lumigraph.bench:main", "speed against error, ours beside the peers"),
    Method("inspect", "lumigraph.inspect:main", "describe and validate images, stacks and artifacts"),
    Method("view", "lumigraph.view.cli:main",
           "a local web page: look at artifacts, mark Façade edges and solve"),
])


def _load_stage(name: str) -> Callable[..., int]:
    return STAGES[name].load()


def _top_help() -> str:
    lines = ["usage: lumigraph [--version] STAGE [VERB] ...", "",
             "Image-based capture and reconstruction: calibration, HDR, flow and stereo,",
             "light fields and direct/global separation, as commands that read and",
             "write ordinary files (EXR, PFM, .flo, PLY, JSON).", "", "stages:"]
    lines += [f"  {m.name:<11} {m.help}" for m in STAGES.values()]
    lines += ["", "Each stage explains itself: lumigraph STAGE --help",
              "Also runnable as python -m lumigraph (a stage: python -m lumigraph.hdr ...).",
              "Exit status: 0 done; 1 an internal fault (our bug: report it); 2 bad input or",
              "usage, one line on stderr, nothing written; 3 the work ran but its result is not",
              "usable; 4 a batch with some items failed; 130 interrupted."]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``lumigraph`` console script."""
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C while the stage's libraries load: no traceback
        from lumigraph.capture.commandline import committed_status

        if (status := committed_status()) is not None:  # on the way out, the result written
            return status
        sys.stderr.write("error: interrupted; nothing was written\n")
        return EXIT_INTERRUPTED


def _main(argv: Sequence[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_top_help())
        return EXIT_OK if argv else EXIT_USAGE
    if argv[0] == "--version":
        from lumigraph import __version__

        print(f"lumigraph {__version__}")
        return EXIT_OK
    stage = argv[0]
    if stage not in STAGES:
        sys.stderr.write(f"error: lumigraph: unknown stage {stage!r}; choose from "
                         f"{', '.join(STAGES)} (see 'lumigraph --help')\n")
        return EXIT_USAGE
    try:
        stage_main = _load_stage(stage)
    except ModuleNotFoundError as e:
        sys.stderr.write(f"error: lumigraph {stage}: this installation lacks {e.name} "
                         "(reinstall lumigraph)\n")
        return EXIT_INTERNAL
    return stage_main(argv[1:], prog=f"lumigraph {stage}")


if __name__ == "__main__":
    raise SystemExit(main())
