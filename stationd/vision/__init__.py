"""Marker localization: pure functions on NumPy arrays (no devices, no database).

Pipeline (paper sections 2-3): enhance -> segment -> edges -> ellipse -> centre; ``detect``
runs it on one image, ``stereo`` (in ``stationd.geometry``) combines two views.
"""
