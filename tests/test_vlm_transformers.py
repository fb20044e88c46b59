"""The transformers backend, through its real loading code, on a tiny random Qwen2-VL saved to a temp dir."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from annotation.checkpoints import fingerprint
from annotation.vlm import PROMPT_VERSION, make_backend
from dataset.synthetic import render_video

torch = pytest.importorskip("torch")
transformers = pytest.importorskip("transformers")

SPECIAL = ["<|endoftext|>", "<|im_start|>", "<|im_end|>", "<|vision_start|>", "<|vision_end|>"]
SPECIAL += ["<|image_pad|>", "<|video_pad|>"]
WORDS = ["yes", "no", ",", ".", "the", "image", "is", "a", "room", "wall", "mirror", "blurry", "sharp", "maybe", "not"]
# Qwen2-VL's chat template, less the video and multi-image numbering branches.
CHAT_TEMPLATE = (
    "{% for message in messages %}{% if loop.first and message['role'] != 'system' %}"
    "<|im_start|>system\nYou are a helpful assistant.<|im_end|>\n{% endif %}"
    "<|im_start|>{{ message['role'] }}\n{% if message['content'] is string %}{{ message['content'] }}<|im_end|>\n"
    "{% else %}{% for content in message['content'] %}{% if content['type'] == 'image' %}"
    "<|vision_start|><|image_pad|><|vision_end|>{% elif content['type'] == 'text' %}{{ content['text'] }}{% endif %}"
    "{% endfor %}<|im_end|>\n{% endif %}{% endfor %}{% if add_generation_prompt %}<|im_start|>assistant\n{% endif %}"
)


def save_tiny_qwen2_vl(directory: Path) -> Path:
    """A randomly initialised Qwen2-VL of a few hundred kB with a word-level tokenizer, all offline."""
    from tokenizers import Tokenizer, models, pre_tokenizers
    from transformers import PreTrainedTokenizerFast, Qwen2VLConfig, Qwen2VLForConditionalGeneration
    from transformers.models.qwen2_vl.image_processing_pil_qwen2_vl import Qwen2VLImageProcessorPil

    vocab = {token: i for i, token in enumerate(["<unk>", *WORDS, *SPECIAL])}
    word_level = Tokenizer(models.WordLevel(vocab=vocab, unk_token="<unk>"))
    word_level.pre_tokenizer = pre_tokenizers.WhitespaceSplit()
    tokenizer = PreTrainedTokenizerFast(
        tokenizer_object=word_level,
        unk_token="<unk>",
        pad_token="<|endoftext|>",
        eos_token="<|im_end|>",
        additional_special_tokens=SPECIAL,
    )
    tokenizer.chat_template = CHAT_TEMPLATE
    config = Qwen2VLConfig(
        text_config={
            "vocab_size": len(vocab),
            "hidden_size": 32,
            "intermediate_size": 64,
            "num_hidden_layers": 2,
            "num_attention_heads": 4,
            "num_key_value_heads": 2,
            "max_position_embeddings": 1024,
            "rope_parameters": {"rope_type": "default", "rope_theta": 10000.0, "mrope_section": [2, 1, 1]},
            "bos_token_id": vocab["<|endoftext|>"],
            "eos_token_id": vocab["<|im_end|>"],
            "pad_token_id": vocab["<|endoftext|>"],
        },
        vision_config={"depth": 1, "embed_dim": 32, "hidden_size": 32, "num_heads": 2, "mlp_ratio": 2},
        image_token_id=vocab["<|image_pad|>"],
        video_token_id=vocab["<|video_pad|>"],
        vision_start_token_id=vocab["<|vision_start|>"],
        vision_end_token_id=vocab["<|vision_end|>"],
    )
    torch.manual_seed(0)
    model = Qwen2VLForConditionalGeneration(config)
    with torch.no_grad():
        # Special tokens get zero logits, so the noise never stops early and always decodes to words.
        model.lm_head.weight[[vocab[t] for t in SPECIAL]] = 0.0
    model.save_pretrained(directory)
    tokenizer.save_pretrained(directory)
    Qwen2VLImageProcessorPil(min_pixels=56 * 56, max_pixels=112 * 112).save_pretrained(directory)
    return directory


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_tiny_qwen2_vl(tmp_path_factory.mktemp("tiny-qwen2-vl"))


def test_tiny_checkpoint_loads_and_noise_becomes_unparsed(tiny_model: Path) -> None:
    landscape = render_video(0, n_frames=2, width=320, height=180).frames[0].left
    portrait = np.ascontiguousarray(landscape[:, :120])  # another size: another image-token count, padded batch
    started = time.perf_counter()
    backend = make_backend("transformers", model_path=tiny_model, concurrency=2)
    verdicts = backend.classify([landscape, portrait])
    elapsed = time.perf_counter() - started
    backend.close()
    assert elapsed < 20
    assert backend.name == "transformers" and backend.prompt_version == PROMPT_VERSION
    assert backend.model_id == f"qwen2_vl:{tiny_model.name}:{fingerprint(tiny_model)}"
    assert len(verdicts) == 2
    for verdict in verdicts:
        assert verdict.raw.strip(), "the noise decodes to words"
        assert not verdict.parsed and verdict.keep is None and verdict.error is None
        assert verdict.reason
        assert verdict.metrics["batch_size"] == 2


def test_bad_images_fail_alone(tiny_model: Path) -> None:
    frame = render_video(1, n_frames=2, width=160, height=90).frames[0].left
    backend = make_backend("transformers", model_path=tiny_model, concurrency=4)
    verdicts = backend.classify([np.zeros((5, 5), np.uint8), frame])
    assert verdicts[0].error is not None and "invalid image" in verdicts[0].error
    assert verdicts[1].error is None and verdicts[1].raw


def test_a_failing_batch_fails_only_its_own_frames(tiny_model: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    frame = render_video(2, n_frames=2, width=160, height=90).frames[0].left
    backend = make_backend("transformers", model_path=tiny_model, concurrency=1)
    generate = backend._model.generate
    calls = []

    def out_of_memory_once(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("CUDA out of memory")
        return generate(*args, **kwargs)

    monkeypatch.setattr(backend._model, "generate", out_of_memory_once)
    first, second = backend.classify([frame, frame])
    assert first.error == "generation failed (RuntimeError: CUDA out of memory)" and first.keep is None
    assert second.error is None and second.raw


def test_a_directory_without_a_model_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="not a Qwen2-VL checkpoint directory") as raised:
        make_backend("transformers", model_path=tmp_path)
    assert "\n" not in str(raised.value)
    with pytest.raises(ValueError, match="not a directory"):
        make_backend("transformers", model_path=tmp_path / "missing")
