"""``python -m lumigraph.view`` == ``lumigraph view``."""

from lumigraph.view.cli import main

raise SystemExit(main(prog="lumigraph view"))
