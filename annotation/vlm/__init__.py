"""VLM prefilter: the paper's 12-question prompt, a tolerant answer parser, the authors' keep rule,
their sparse sampling, and backends (heuristic default, OpenAI-compatible server, local transformers).

No Flask, DB or settings here: callers pass configuration in (see ``make_backend``).
"""

from annotation.vlm.backends import BACKEND_NAMES, PrefilterBackend, answered_questions, make_backend
from annotation.vlm.parse import ParsedAnswers, format_answers, parse_answers
from annotation.vlm.prompt import PROMPT, PROMPT_VERSION, QUESTION_LABELS, QUESTIONS
from annotation.vlm.rule import KeepRule
from annotation.vlm.sparse import sparse_expand, sparse_samples, sparse_step
from annotation.vlm.verdict import Verdict

__all__ = [
    "BACKEND_NAMES",
    "PROMPT",
    "PROMPT_VERSION",
    "QUESTIONS",
    "QUESTION_LABELS",
    "KeepRule",
    "ParsedAnswers",
    "PrefilterBackend",
    "Verdict",
    "answered_questions",
    "format_answers",
    "make_backend",
    "parse_answers",
    "sparse_expand",
    "sparse_samples",
    "sparse_step",
]
