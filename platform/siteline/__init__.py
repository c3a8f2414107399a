"""siteline: drone surveys of construction sites turned into change-detection datasets."""

__version__ = "0.1.0"
