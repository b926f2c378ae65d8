"""Dense multi-view stereo on the final map (issue 7).

Stage entry point: :func:`scenebot.dense.stage.run`, configured by
:class:`scenebot.dense.config.DenseConfig`.
Modules: ``workspace`` (pycolmap undistortion, COLMAP dense workspace), ``views`` (source-view
selection), ``patchmatch`` (taichi PatchMatch stereo, CPU or GPU), ``colmap_io`` (COLMAP depth /
normal map files), ``evaluate`` (metrics against true geometry), ``plots``. Test scenes with
known depth: :mod:`scenebot.testing.dense`.
"""
