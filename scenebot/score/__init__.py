"""The score stage (paper IV.B): random candidate viewpoints in the free space, each scored by
the unstructured-lumigraph angle heuristic that predicts how well a synthesized image there
would turn out. Entry point :func:`scenebot.score.stage.run`; settings in
:mod:`scenebot.score.config`; the taichi scorer in :mod:`scenebot.score.kernel` and its numpy
reference in :mod:`scenebot.score.reference`.
"""
