"""``python -m stereo …`` is ``lumigraph stereo …``."""

from stereo.cli import main

raise SystemExit(main(prog="python -m stereo"))
