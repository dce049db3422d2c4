"""Seeing maps: labelled figures (matplotlib, imported on first use), and what notebooks show.

:mod:`occmap.viz.figure` holds what every figure shares (axes in metres, scale bar, crop, atomic
PNG write); :mod:`occmap.viz.maps` the figures of grids and octrees.
"""
