"""Turning videos into frames: sources (video files, synthetic scenes), sampling, near-duplicate hashing."""

from dataset.ingest.phash import dhash, hamming
from dataset.ingest.sources import DecodedFrame, FrameSource, IngestError, SourceInfo, find_sources, open_source

__all__ = ["DecodedFrame", "FrameSource", "IngestError", "SourceInfo", "dhash", "find_sources", "hamming", "open_source"]
