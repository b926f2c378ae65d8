"""The goals stage (paper IV.B): the best candidates as the next round's goals
(:mod:`~scenebot.goals.select`, or the frontier baseline :mod:`~scenebot.goals.frontier`), and
whether the map is complete (:mod:`~scenebot.goals.stopping`, the stopping rule in one place);
the entry point is :func:`scenebot.goals.stage.run`.
"""
