from lumigraph.capture.commandline import module_main

raise SystemExit(module_main("lumigraph.lightfield.cli", "python -m lumigraph.lightfield"))
