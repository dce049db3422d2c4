"""Fixtures of the bag tests."""

from __future__ import annotations

import pytest

from occmap.errors import FormatError


@pytest.fixture
def reader_for(monkeypatch):
    """``reader_for(kind)``: for ``ros1_chunks``, make rosbags refuse ROS 1 bags as it refuses the
    shared bag's index, so that ROS 1 bags are read from their chunk records."""
    from occmap.io.bags import bag as bag_module

    def use(kind):
        if kind == "ros1_chunks":
            real = bag_module._Rosbags

            def refuse_ros1(path, what):
                if what == "ROS 1":
                    raise FormatError(path, "refused in this test") from AssertionError()
                return real(path, what)

            monkeypatch.setattr(bag_module, "_Rosbags", refuse_ros1)

    return use
