"""Python tools for pedscan's labeled LiDAR sequences: a lazy reader of sequence files and
folders."""

from .reader import BEAM_FIELDS, Frame, Humans, PedscanError, Sequence, open_sequences, sequence_paths

__all__ = [
    "BEAM_FIELDS",
    "Frame",
    "Humans",
    "PedscanError",
    "Sequence",
    "open_sequences",
    "sequence_paths",
]
