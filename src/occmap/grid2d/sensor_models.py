"""Inverse sensor models: how much one reading moves a cell's log-odds.

Log-odds ``l = log(p / (1 − p))``; a reading adds ``l_sensor − l_prior`` to every cell it
speaks about (the static-state binary Bayes filter, Thrun et al., *Probabilistic Robotics* §4.2).
Defaults are OctoMap's: hit 0.7, miss 0.4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InvalidArgumentError


def logit(p: float) -> float:
    """``log(p / (1 − p))`` for ``0 < p < 1``."""
    if not 0.0 < p < 1.0:
        raise InvalidArgumentError(f"probability must be in (0, 1), got {p!r}")
    return math.log(p / (1.0 - p))


@dataclass(frozen=True)
class LidarModel:
    """Beam-end model of a laser: the end cell of a return is hit, the cells before it are free.

    ``p_hit`` is P(occupied | return ends in the cell), ``p_miss`` is P(occupied | beam passes
    through the cell); both must lie on their side of 0.5.
    """

    p_hit: float = 0.7
    p_miss: float = 0.4

    def __post_init__(self):
        if not 0.5 < self.p_hit < 1.0:
            raise InvalidArgumentError(f"p_hit must be in (0.5, 1), got {self.p_hit!r}")
        if not 0.0 < self.p_miss < 0.5:
            raise InvalidArgumentError(f"p_miss must be in (0, 0.5), got {self.p_miss!r}")

    @property
    def l_hit(self) -> float:
        return logit(self.p_hit)

    @property
    def l_miss(self) -> float:
        return logit(self.p_miss)


@dataclass(frozen=True)
class SonarModel:
    """Cone model of a sonar transducer (after Moravec & Elfes, "High resolution maps from wide
    angle sonar", ICRA 1985, as taught in Thrun et al. §9.2).

    An echo at range ``r`` says: some obstacle lies on the arc of the cone at ``r`` (cells within
    ``arc`` metres of it get occupied evidence), and the cone before the arc is free. Both are
    weighted by ``w = 1 − (φ / (beam_width/2))²``, ``φ`` the angle of the cell centre from the
    axis, so the axis speaks loudest and the rim not at all. A reading at or beyond the maximum
    range clears the cone up to it. ``arc=None`` uses one cell.
    """

    beam_width: float = math.radians(15.0)
    p_occupied: float = 0.7
    p_free: float = 0.4
    arc: float | None = None

    def __post_init__(self):
        if not 0.0 < self.beam_width < math.pi:
            raise InvalidArgumentError(f"beam_width must be in (0, π) radians, got {self.beam_width!r}")
        if not 0.5 < self.p_occupied < 1.0:
            raise InvalidArgumentError(f"p_occupied must be in (0.5, 1), got {self.p_occupied!r}")
        if not 0.0 < self.p_free < 0.5:
            raise InvalidArgumentError(f"p_free must be in (0, 0.5), got {self.p_free!r}")
        if self.arc is not None and not self.arc > 0:
            raise InvalidArgumentError(f"arc must be a positive thickness in metres, got {self.arc!r}")

    @property
    def l_occupied(self) -> float:
        return logit(self.p_occupied)

    @property
    def l_free(self) -> float:
        return logit(self.p_free)
