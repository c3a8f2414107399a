"""Loading releases for training: a torch Dataset and joint transforms."""

from siteline.data.dataset import ChangeDetectionDataset
from siteline.data.transforms import TrainTransforms

__all__ = ["ChangeDetectionDataset", "TrainTransforms"]
