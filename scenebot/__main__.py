from scenebot.cli import main

raise SystemExit(main())
