"""``python -m lumigraph …`` is the ``lumigraph`` command."""

from lumigraph.command import main

raise SystemExit(main())
