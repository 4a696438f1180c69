"""``python -m lumigraph.separation …`` is ``lumigraph separate …``."""

from lumigraph.separation.cli import main

raise SystemExit(main(prog="python -m lumigraph.separation"))
