"""``python -m lumigraph.stereo …`` is ``lumigraph stereo …``."""

from lumigraph.capture.commandline import module_main

raise SystemExit(module_main("lumigraph.stereo.cli", "python -m lumigraph.stereo"))
