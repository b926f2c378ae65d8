"""The capture stage: the robot takes the photos of a round (paper IV.A and IV.C).

- :mod:`~scenebot.capture.stage`: round 0, random exploration (``run_capture``), and the
  trajectory picture;
- :mod:`~scenebot.capture.adaptive`: rounds >= 1, drive to the previous round's goals
  (``run_adaptive``) with :mod:`~scenebot.capture.follow` (path following with visual
  localization) and take photos there;
- :mod:`~scenebot.capture.explore`: the exploration moves (circles of photos, ultrasonic and
  compass, bumpers);
- :mod:`~scenebot.capture.session`: what every capture does with its folder (lock, archive of an
  earlier attempt, the capture log's first and last records).

The capture log it writes is read with :mod:`scenebot.capturelog` (shared by every stage).
"""
