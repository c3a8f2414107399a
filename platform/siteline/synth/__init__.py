"""The synthetic construction site: the embedded default data, with ground truth."""

from siteline.synth.mission import LAS_RELPATH, SynthParams, write_epoch, write_site
from siteline.synth.model import EpochSpec, SiteModel

__all__ = ["LAS_RELPATH", "EpochSpec", "SiteModel", "SynthParams", "write_epoch", "write_site"]
