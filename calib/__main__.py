"""``python -m calib …`` is ``lumigraph calib …``."""

from calib.cli import main

raise SystemExit(main(prog="python -m calib"))
