"""``python -m lumigraph.hdr …`` is ``lumigraph hdr …``."""

from lumigraph.capture.commandline import module_main

raise SystemExit(module_main("lumigraph.hdr.cli", "python -m lumigraph.hdr"))
