"""The FC-Siam-diff baseline: model, training and evaluation on a release."""

from siteline.baseline.model import FCSiamDiff, parameter_count
from siteline.baseline.train import TrainParams, class_weights, evaluate, train

__all__ = ["FCSiamDiff", "TrainParams", "class_weights", "evaluate", "parameter_count", "train"]
