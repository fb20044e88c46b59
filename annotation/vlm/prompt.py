"""The paper's 12-question prefilter prompt (appendix "Prompts", used with Qwen2-VL-72B).

The text is the paper's verbatim, with LaTeX quotes (`yes') rendered as ASCII quotes ('yes');
the paper's unbalanced quote in "Each 'yes or 'no'" is kept so that results stay comparable
with the authors'. Any change to the wording is a new PROMPT_VERSION: every stored result
records the version it was asked with.
"""

from __future__ import annotations

PROMPT_VERSION = "paper-v1"

INSTRUCTION = (
    "Reply to me in the format of a string concatenating 'yes' or 'no' with ','. "
    "Each 'yes or 'no' is an answer to each following question."
)

QUESTIONS: tuple[str, ...] = (
    "Does this image feature any flat artistic creation of landscapes where the surface of the creation is "
    "flat and has no ups and downs?",
    "Does this image contain any areas with perspective illusions?",
    "Does this image contain any optical-illusion graffiti or artwork?",
    "Does this image contain any transparent or high-reflective areas?",
    "Does this image show a display screen playing 3D objects or scenes?",
    "Does the image contain areas that make you mistake them for 3D objects?",
    "Does this image contain excessive watermarks or captions that seriously affect its quality?",
    "Does this image contain small watermarks or captions in the corners?",
    "Is this image too blurry?",
    "Are most regions of the artistic creation covered by a single/two hands?",
    "Is this image a software interface?",
    "Is only the figure of the artist clear, but the others are blurry, like artwork, screen, or areas that make "
    "you mistake them for 3D objects?",
)

# Short names for reasons shown to curators ("rejected: Q9 (too blurry) yes").
QUESTION_LABELS: tuple[str, ...] = (
    "flat artwork",
    "perspective illusion",
    "illusion graffiti/artwork",
    "transparent/reflective",
    "screen showing 3D",
    "mistaken for 3D",
    "excessive watermark/caption",
    "corner watermark/caption",
    "too blurry",
    "covered by hands",
    "software interface",
    "only the artist sharp",
)

N_QUESTIONS = len(QUESTIONS)

PROMPT = INSTRUCTION + " " + " ".join(QUESTIONS)

# Tokens a model may generate for its reply: "yes, no, …" for 12 questions takes about 24 with
# Qwen's tokenizer, so 48 leaves room for a preamble without paying for long explanations.
ANSWER_TOKEN_BUDGET = 48


def question_label(number: int) -> str:
    """'Q9 (too blurry)' for a 1-based question number."""
    return f"Q{number} ({QUESTION_LABELS[number - 1]})"
