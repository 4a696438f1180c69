"""``python -m lumigraph.hdr …`` is ``lumigraph hdr …``."""

from lumigraph.hdr.cli import main

raise SystemExit(main(prog="python -m lumigraph.hdr"))
