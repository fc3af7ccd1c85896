"""Data: demonstrations on disk, chunk windows for training, and normalisation."""

from coursekit.data.chunks import ActionChunks, SequenceWindows
from coursekit.data.episodes import DatasetError, EpisodeDataset
from coursekit.data.normalize import MeanStdNormalizer, MinMaxNormalizer, normalizer_from_state

__all__ = ["ActionChunks", "DatasetError", "EpisodeDataset", "MeanStdNormalizer", "MinMaxNormalizer",
           "SequenceWindows", "normalizer_from_state"]
