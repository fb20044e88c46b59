"""Deterministic synthetic illusion scenes: stereo videos of simple rooms with a picture
(a flat canvas depicting a deeper room) and a mirror, with exact ground truth.

Every frame has an exactly rendered left/right pair, the true disparity, the disparity a
monocular estimator is fooled into — exactly (``mono_ideal``: depicted depth inside the picture,
reflected depth inside the mirror) and as a real network reports it (``mono_disparity``:
relative, coarse, partly fooled by the mirror; ``dataset.synthetic.mono``) —, the disparity a
stereo matcher is fooled into (reflected depth inside the mirror), and illusion/support masks.
These are the demo data and the test ground truth.
"""

from dataset.synthetic.io import read_video, write_synthetic_dataset, write_video
from dataset.synthetic.records import RegionPair, SyntheticFrame, SyntheticVideo
from dataset.synthetic.render import render_video

__all__ = [
    "RegionPair",
    "SyntheticFrame",
    "SyntheticVideo",
    "read_video",
    "render_video",
    "write_synthetic_dataset",
    "write_video",
]
