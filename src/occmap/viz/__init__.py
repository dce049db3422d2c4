"""Seeing maps: labelled figures (matplotlib, imported on first use), what notebooks show, and the
interactive 3D viewer in the browser.

:mod:`occmap.viz.figure` holds what every figure shares (axes in metres, scale bar, crop, atomic
PNG write); :mod:`occmap.viz.maps` the figures of grids and octrees; :mod:`occmap.viz.viewer` the
viewer behind ``occmap view`` (viser, imported on first use).
"""
