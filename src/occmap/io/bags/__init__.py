"""ROS bags: ROS 1 ``.bag``, ROS 2 folders, ``.db3`` and ``.mcap`` files, read as streams of
messages (:mod:`.bag`) and decoded into occmap's arrays."""

from .bag import Bag, Message, Topic, open_bag

__all__ = ["Bag", "Message", "Topic", "open_bag"]
