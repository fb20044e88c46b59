"""Illusion proposals: proposers draft illusion/support mask pairs for a frame, the annotator confirms.

Proposers: ``plane-break`` (weight-free default: breaks of planar surfaces in the monocular
disparity) and ``vlm`` (the paper's corner prompt through the VLM backend, boxes to the segmenter).
"""

from annotation.proposals.base import ILLUSION_TYPES, Proposal, ProposalError, Proposals, Proposer
from annotation.proposals.registry import PROPOSERS, make_proposers

__all__ = ["ILLUSION_TYPES", "PROPOSERS", "Proposal", "ProposalError", "Proposals", "Proposer", "make_proposers"]
