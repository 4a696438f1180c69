"""``python -m lumigraph.stereo …`` is ``lumigraph stereo …``."""

from lumigraph.stereo.cli import main

raise SystemExit(main(prog="python -m lumigraph.stereo"))
