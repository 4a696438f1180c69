"""``python -m separation …`` is ``lumigraph separate …``."""

from separation.cli import main

raise SystemExit(main(prog="python -m separation"))
