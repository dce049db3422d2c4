"""Localization in a known map: Monte Carlo localization (ROS AMCL's particle filter) and the
replay of a recorded log against a map (``occmap localize``)."""

from .mcl import LocalizationWarning, MonteCarloLocalizer, PoseEstimate
from .params import LocalizationParams

__all__ = ["LocalizationParams", "LocalizationWarning", "MonteCarloLocalizer", "PoseEstimate"]
