"""``python -m lumigraph.capture …`` is ``lumigraph render …``."""

from lumigraph.capture.cli import main

raise SystemExit(main(prog="python -m lumigraph.capture"))
