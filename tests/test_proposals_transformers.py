"""The transformers backend's free prompt, as the vlm proposer asks it (a tiny random Qwen2-VL)."""

from __future__ import annotations

from pathlib import Path

import pytest

from annotation.proposals.vlm import CORNER_PROMPT, VlmProposer
from annotation.segment import make_segmenter
from annotation.vlm import make_backend
from annotation.vlm.backends.base import AskError, FreePromptBackend
from dataset.synthetic import render_video
from tests.test_vlm_transformers import save_tiny_qwen2_vl


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_tiny_qwen2_vl(tmp_path_factory.mktemp("tiny-qwen2-vl"))


def test_the_transformers_backend_answers_a_free_prompt_and_noise_proposes_nothing(tiny_model: Path) -> None:
    frame = render_video(307, n_frames=1, width=160, height=90).frames[0].left
    backend = make_backend("transformers", model_path=tiny_model, concurrency=1)
    assert isinstance(backend, FreePromptBackend)
    reply = backend.ask(frame, CORNER_PROMPT, 12)
    assert isinstance(reply, str) and reply.strip(), "the noise decodes to words"
    with pytest.raises(AskError, match="invalid image"):
        backend.ask(frame[:, :, 0], CORNER_PROMPT, 12)
    found = VlmProposer(backend, make_segmenter("classical")).propose(frame)
    backend.close()
    assert found.items == [] and found.note == ""
