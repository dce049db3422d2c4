"""Shared fixtures: one seeded batch of random rotations built with scipy (not with occmap), so
cross-checks against scipy never compare occmap with itself."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import settings

# Opt-in: `pytest --hypothesis-profile=thorough` runs every property test (those without their own
# max_examples) with 30x the default examples, to shake out tolerances that are too tight.
settings.register_profile("thorough", max_examples=3000, deadline=None)


@pytest.fixture(scope="session")
def scipy_rotations():
    """10,000 random rotations (fixed seed) as a scipy ``Rotation``, drawn by scipy itself."""
    from scipy.spatial.transform import Rotation

    return Rotation.random(10_000, rng=np.random.default_rng(20240611))


@pytest.fixture
def rng():
    """A fresh, seeded NumPy generator per test."""
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def data_dir():
    """The shared real-robot data: ``$OCCMAP_DATA`` or ``../shared/data`` beside the project.
    Tests that need it are skipped, saying why, when neither exists."""
    from pathlib import Path

    from occmap._data import find_shared_data

    found = find_shared_data(Path(__file__).resolve().parent)
    if found is None:
        pytest.skip("real robot data not found: set OCCMAP_DATA or place it at ../shared/data")
    return found
