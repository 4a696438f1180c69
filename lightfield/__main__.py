from lumigraph.lightfield.cli import main

raise SystemExit(main(prog="python -m lumigraph.lightfield"))
