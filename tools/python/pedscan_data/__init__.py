"""Python tools for pedscan's labeled LiDAR sequences: a lazy reader, N-frame training
windows (numpy, or PyTorch when installed) and an evaluator of segmentation predictions."""

from .reader import BEAM_FIELDS, Frame, Humans, PedscanError, Sequence, open_sequences, sequence_paths
from .windows import TorchWindowDataset, WindowDataset, class_weight

__all__ = [
    "BEAM_FIELDS",
    "Frame",
    "Humans",
    "PedscanError",
    "Sequence",
    "TorchWindowDataset",
    "WindowDataset",
    "class_weight",
    "open_sequences",
    "sequence_paths",
]
