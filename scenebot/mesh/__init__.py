"""The mesh stage (paper IV.B): the Poisson surface of a round's map
(:mod:`~scenebot.mesh.poisson`) and the free space it leaves at the camera plane
(:mod:`~scenebot.mesh.freespace`); the entry point is :func:`scenebot.mesh.stage.run`.
"""
