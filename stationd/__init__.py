"""stationd: the software of a vision-guided bolt-tightening station."""

__version__ = "0.1.0"
