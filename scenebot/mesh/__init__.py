"""The mesh stage (paper IV.B): the Poisson surface of a round's map
(:mod:`~scenebot.mesh.poisson`) and the free space it leaves at the camera plane
(:mod:`~scenebot.mesh.freespace`), or for a person's photos (``robot: photos``) the 3-D space
the photos saw through (:mod:`~scenebot.mesh.volume`); the entry point is
:func:`scenebot.mesh.stage.run`.
"""
