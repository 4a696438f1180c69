"""``python -m lumigraph.calib …`` is ``lumigraph calib …``."""

from lumigraph.calib.cli import main

raise SystemExit(main(prog="python -m lumigraph.calib"))
