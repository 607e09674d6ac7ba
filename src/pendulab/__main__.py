from pendulab.cli.main import main

raise SystemExit(main())
