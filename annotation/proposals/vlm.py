"""``vlm``: the paper's prompt for reflective and transparent objects, answered with corner
coordinates by the configured VLM backend; each quadrilateral's bounding box prompts the configured
segmenter, whose mask is the proposal.

Answers are read tolerantly: every bracketed group of exactly eight numbers is a quadrilateral, in
pixels, or in fractions of the image (all ≤ 1), or on Qwen2-VL's 0–1000 grid (when pixels would
leave the image). Anything else — prose, half a quadrilateral, a box of no area — is no proposal,
never an error.
"""

from __future__ import annotations

import re

import numpy as np

from annotation.proposals.base import Proposal, Proposals, check_frame, ring_support, suppress_overlaps
from annotation.segment.base import Segmenter
from annotation.vlm.backends.base import AskError, FreePromptBackend, PrefilterBackend

# The paper's prompt for the VLM (appendix "Prompts"), word for word.
CORNER_PROMPT = ("Are there any transparent or reflective objects? Like mirror, glass, window, showcase, and so on? "
                 "If true, reply to me with the list of corner coordinates of each object in the format of "
                 "(x1,y1,x2,y2,x3,y3,x4,y4) in the image. If false, reply with an empty list of corners.")
ANSWER_TOKENS = 256
MIN_SIDE_PX = 4  # a box thinner than this is no object
RING_FRACTION = 0.04  # support ring width, of the image width
_GROUP = re.compile(r"[(\[]([^()\[\]]*)[)\]]")
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def parse_corners(text: str, width: int, height: int) -> list[np.ndarray]:
    """The quadrilaterals of a reply, each (4, 2) float (x, y) pixels clipped to the image (module doc)."""
    quads = []
    for group in _GROUP.findall(text or ""):
        numbers = [float(n) for n in _NUMBER.findall(group)]
        if len(numbers) != 8:
            continue
        corners = np.array(numbers).reshape(4, 2)
        if corners.max() <= 1.0:
            corners *= (width, height)
        elif (corners[:, 0].max() > width or corners[:, 1].max() > height) and corners.max() <= 1000:
            corners *= (width / 1000, height / 1000)
        corners = np.clip(corners, 0, (width - 1, height - 1))
        if np.ptp(corners[:, 0]) >= MIN_SIDE_PX and np.ptp(corners[:, 1]) >= MIN_SIDE_PX:
            quads.append(corners)
    return quads


class VlmProposer:
    """Proposals from the VLM's corners and the segmenter's box masks (see module doc)."""

    name = "vlm"
    needs_mono = False

    def __init__(self, backend: PrefilterBackend, segmenter: Segmenter) -> None:
        """``backend``: the configured VLM backend (one without ``ask`` yields no proposals);
        ``segmenter``: the configured segmenter, prompted with each quadrilateral's box."""
        self._backend = backend
        self._segmenter = segmenter

    def propose(self, image: np.ndarray, mono: np.ndarray | None = None) -> Proposals:
        """Proposals, best first; none (with a note) when the backend cannot be asked or did not answer."""
        image, _ = check_frame(image, mono)
        if not isinstance(self._backend, FreePromptBackend):
            return Proposals(note=f"the {self._backend.name} VLM backend answers no free prompt: "
                                  "configure the openai or transformers backend")
        try:
            reply = self._backend.ask(image, CORNER_PROMPT, ANSWER_TOKENS)
        except AskError as exc:
            return Proposals(note=f"the VLM gave no answer: {exc}")
        height, width = image.shape[:2]
        quads = parse_corners(reply, width, height)
        if not quads:
            return Proposals()
        embedding = self._segmenter.encode(image)
        found = []
        for corners in quads:
            box = (*corners.min(axis=0), *corners.max(axis=0))
            best = self._segmenter.predict(embedding, np.zeros((0, 2)), np.zeros(0, np.int64), box=box)[0]
            if best.mask.any():
                support = ring_support(best.mask, round(RING_FRACTION * width))
                found.append(Proposal(best.mask, support, None, float(np.clip(best.score, 0, 1)), self.name))
        return Proposals(suppress_overlaps(found))
