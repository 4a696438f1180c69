from capture.command import main

raise SystemExit(main())
