"""``python -m lumigraph.capture …`` is ``lumigraph render …``."""

from lumigraph.capture.commandline import module_main

raise SystemExit(module_main("lumigraph.capture.cli", "python -m lumigraph.capture"))
