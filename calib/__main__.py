"""``python -m lumigraph.calib …`` is ``lumigraph calib …``."""

from lumigraph.capture.commandline import module_main

raise SystemExit(module_main("lumigraph.calib.cli", "python -m lumigraph.calib"))
