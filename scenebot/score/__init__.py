"""Choosing where to look next (paper IV.B): mesh, free space, candidates, score, goals.

Stage entry points live in :mod:`scenebot.score.stage` (``run_mesh``, ``run_score``,
``run_goals``); settings in :mod:`scenebot.score.config`; the taichi scorer in
:mod:`scenebot.score.kernel` and its numpy reference in :mod:`scenebot.score.reference`.
"""
