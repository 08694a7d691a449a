from e4dgs.cli import main

raise SystemExit(main())
