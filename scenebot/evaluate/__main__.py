"""``python -m scenebot.evaluate``: see :mod:`scenebot.evaluate.cli`."""

from scenebot.evaluate.cli import main

raise SystemExit(main())
