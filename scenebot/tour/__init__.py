"""The virtual tour (issue 8): unstructured lumigraph rendering on the dense cloud, a tour
path, a video and a static web viewer.

Modules: :mod:`~scenebot.tour.ulr` (renderer), :mod:`~scenebot.tour.proxy` (point-cloud
proxy), :mod:`~scenebot.tour.path`, :mod:`~scenebot.tour.video`, :mod:`~scenebot.tour.viewer`,
:mod:`~scenebot.tour.evaluate`, :mod:`~scenebot.tour.stage` (entry point ``run``),
:mod:`~scenebot.tour.config` (``TourConfig``).
"""
