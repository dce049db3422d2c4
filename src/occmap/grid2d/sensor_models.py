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
