"""``python -m lumigraph.separation …`` is ``lumigraph separate …``."""

from lumigraph.capture.commandline import module_main

raise SystemExit(module_main("lumigraph.separation.cli", "python -m lumigraph.separation"))
