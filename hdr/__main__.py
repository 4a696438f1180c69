"""``python -m hdr …`` is ``lumigraph hdr …``."""

from hdr.cli import main

raise SystemExit(main(prog="python -m hdr"))
