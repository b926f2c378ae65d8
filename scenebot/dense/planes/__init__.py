"""The steps of the plane fill of the depth maps, one module each, in the order
:func:`scenebot.dense.planefill.plane_fill` (the entry point, whose docstring explains the
method) runs them:

* ``geometry``: :class:`~scenebot.dense.planes.geometry.Plane` (a plane and its extent
  raster), back-projection and the ray-plane tests the other steps share,
* ``detect``: the thinned cloud of the measured depth and the planes peeled off it by RANSAC,
* ``ceiling``: the ceiling, too small a share of the cloud for RANSAC,
* ``phantoms``: planes the measured depth contradicts (seen through, hidden, shadows),
* ``extents``: the room's boundary planes widened (carved hulls, walls to the ceiling,
  floor and ceiling to the walls),
* ``labels``: each measured pixel's plane and the votes of a hole's nearest measured cells,
* ``fill``: the hole pixels filled from the planes,
* ``vetoes``: filled pixels emptied again (behind measured depth, against the SfM points),
* ``store``: the planes written for the pictures and for users.
"""
