"""The scenebot tests (a package, so that ``tests.fixtures`` imports under any pytest runner)."""
