"""Moving objects around the robot: detection (:mod:`.detection`: clusters of the returns the
static map does not explain, each with an oriented box), one constant turn rate and velocity EKF
per object (:mod:`.ekf`), gated global nearest-neighbour assignment (:mod:`.assignment`) and track
management (:mod:`.tracker`)."""

from .detection import Detections, detect_objects
from .tracker import Tracker, TrackerParams, Tracks

__all__ = ["Detections", "Tracker", "TrackerParams", "Tracks", "detect_objects"]
