"""Readers and writers: bytes in, plain arrays and :class:`~occmap.scan.LaserScan` records out."""
