"""Two ``bench fusion`` records compared on the same held-out pairs: how a design is decided by interval.

Each record keeps every frame's EPE and bad-2 per region and seed (``per_frame``). Two records that
scored the same pairs (equal ``pairs.sha256``) are compared frame by frame: each record's seeds are
averaged per frame, the difference taken, and its mean given with a 95 % interval from the bootstrap
over scenes of ``fusion_stats`` — "lower" or "higher" only where the interval excludes 0.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from benchmarks import fusion_stats as stats
from benchmarks.fusion import REGIONS


def frame_means(record: Mapping[str, Any], method: str, region: str, key: str) -> np.ndarray:
    """(frames,) a method's per-frame ``key`` in ``region``, averaged over the record's seeds (NaN where a
    frame has no pixel of the region). KeyError naming the methods there are when it has no ``method``."""
    methods = record["per_frame"]["methods"]
    if method not in methods:
        raise KeyError(f"no method {method!r} in the record: it holds {', '.join(methods)}")
    return np.array(methods[method][region][key], dtype=np.float64).mean(axis=0)  # a region is a frame's, not a seed's


def compare_records(first: Mapping[str, Any], second: Mapping[str, Any], method: str = "fusion",
                    other: str | None = None) -> dict[str, Any]:
    """``method`` of ``first`` minus ``other`` (default: the same method) of ``second``, per region of
    REGIONS, EPE (px) and bad-2 (%), each ``{"value", "low", "high", "decided"}``. ValueError when the
    records scored different pairs."""
    for record in (first, second):
        if "per_frame" not in record:
            raise ValueError("a record to compare is a `bench fusion --json` of trained networks: it keeps per_frame")
    digests = [record["pairs"]["sha256"] for record in (first, second)]
    if digests[0] != digests[1]:
        raise ValueError(f"the records scored different pairs (sha256 {digests[0][:12]}… and {digests[1][:12]}…): "
                         "only the same split and mono compare")
    other = other or method
    scenes = [frame["scene"] for frame in first["per_frame"]["frames"]]
    out: dict[str, Any] = {"method": method, "other": other, "scenes": len(set(scenes)),
                           "seeds": [first.get("seeds"), second.get("seeds")], "regions": {}}
    for region in REGIONS:
        out["regions"][region] = {}
        for key in ("epe", "bad2"):
            difference = frame_means(first, method, region, key) - frame_means(second, other, region, key)
            found = stats.mean_interval(difference, scenes)
            out["regions"][region][key] = {**stats.rounded(found), "decided": stats.decided(found)}
    return out
