"""mapqual: automatic map-quality evaluation of SLAM algorithms."""

__version__ = "0.1.0"
