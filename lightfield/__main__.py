from lightfield.cli import main

raise SystemExit(main(prog="python -m lightfield"))
