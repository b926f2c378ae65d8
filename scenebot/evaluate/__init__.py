"""Ground-truth evaluation of simulated campaigns (issue 9); truth is read only here.

Modules: ``config`` (:class:`EvaluateConfig`), ``observable`` (the observable surface of a
true scene, cached), ``metrics`` (robot->world similarity, dense accuracy/completeness,
capture and localization figures), ``stage`` (entry points :func:`run_observable` and
:func:`run` of the ``observable`` and ``evaluate`` rules).
"""

from scenebot._lazy import lazy_getattr
from scenebot.evaluate.config import EvaluateConfig

__all__ = ["EvaluateConfig"]

__getattr__ = lazy_getattr(
    __name__,
    ("scenebot.evaluate.stage", "scenebot.evaluate.metrics", "scenebot.evaluate.observable"),
)
