"""Structure from motion of every round, in the robot's frame (issue 3).

Entry point: :func:`scenebot.sfm.stage.run` with :class:`scenebot.sfm.config.SfmConfig`,
:class:`scenebot.sfm.stage.SfmInputs` and :class:`scenebot.sfm.stage.SfmOutputs`.
"""
