"""The sam2 backend end to end on tiny randomly initialised checkpoints saved to a temp dir:
the real from_pretrained load, encode, decode and video propagation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
transformers = pytest.importorskip("transformers")

from annotation.segment import (  # noqa: E402
    Embedding,
    SegmentError,
    make_segmenter,
)

SIZE = 128  # model input side; features at 32, 16 and 8


def _tiny_parts() -> dict:
    """Sub-configs of a tiny SAM2: 5 Hiera blocks, 128-wide neck. The video model hard-codes a
    64-channel memory and splits object pointers into memory-width tokens, so the hidden size
    must be a multiple of 64 larger than 64."""
    hiera = dict(model_type="sam2_hiera_det_model", hidden_size=16, num_attention_heads=1,
                 image_size=[SIZE, SIZE], blocks_per_stage=[1, 1, 2, 1],
                 embed_dim_per_stage=[16, 32, 64, 128], num_attention_heads_per_stage=[1, 1, 2, 2],
                 window_size_per_stage=[4, 4, 4, 4], global_attention_blocks=[3],
                 window_positional_embedding_background_size=[2, 2])
    vision = dict(model_type="sam2_vision_model", backbone_config=hiera,
                  backbone_channel_list=[128, 64, 32, 16],
                  backbone_feature_sizes=[[SIZE // 4] * 2, [SIZE // 8] * 2, [SIZE // 16] * 2],
                  fpn_hidden_size=128)
    return dict(vision_config=vision,
                prompt_encoder_config=dict(hidden_size=128, image_size=SIZE, patch_size=16,
                                           mask_input_channels=4),
                mask_decoder_config=dict(hidden_size=128, mlp_dim=64, num_hidden_layers=1,
                                         num_attention_heads=2, iou_head_hidden_dim=32))


def save_tiny_video_model(path: Path) -> Path:
    """Save a tiny randomly initialised Sam2VideoModel (serves clicks and propagation) to ``path``."""
    torch.manual_seed(0)
    config = transformers.Sam2VideoConfig(
        **_tiny_parts(), image_size=SIZE, num_maskmem=2, max_object_pointers_in_encoder=2,
        memory_attention_hidden_size=128, memory_attention_num_layers=1,
        memory_attention_feed_forward_hidden_size=64,
        memory_attention_rope_feat_sizes=[SIZE // 16, SIZE // 16], memory_encoder_hidden_size=128,
        memory_encoder_output_channels=64, mask_downsampler_embed_dim=128,
        memory_fuser_embed_dim=128, memory_fuser_intermediate_dim=64)
    transformers.Sam2VideoModel(config).save_pretrained(path)
    return path


@pytest.fixture(scope="module")
def video_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_tiny_video_model(tmp_path_factory.mktemp("sam2-video-tiny"))


@pytest.fixture(scope="module")
def image_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A saved tiny Sam2Model (image only) with a processor config of its own."""
    torch.manual_seed(1)
    path = tmp_path_factory.mktemp("sam2-image-tiny")
    transformers.Sam2Model(transformers.Sam2Config(**_tiny_parts())).save_pretrained(path)
    (path / "preprocessor_config.json").write_text(json.dumps(
        {"image_mean": [0.5, 0.5, 0.5], "image_std": [0.25, 0.25, 0.25],
         "size": {"height": SIZE, "width": SIZE}}))
    return path


@pytest.fixture(scope="module")
def video_segmenter(video_dir: Path):
    return make_segmenter("sam2", model_path=video_dir)


def _frames(n: int = 3, h: int = 90, w: int = 160) -> list[np.ndarray]:
    """A bright square drifting right over a gradient background."""
    out = []
    for k in range(n):
        img = np.zeros((h, w, 3), np.uint8)
        img[..., 0] = np.linspace(0, 120, w, dtype=np.uint8)[None, :]
        img[20:60, 30 + 5 * k:80 + 5 * k] = (230, 200, 40)
        out.append(img)
    return out


def test_model_id_names_directory_and_config(video_segmenter, video_dir: Path) -> None:
    assert video_segmenter.name == "sam2"
    prefix, name, digest = video_segmenter.model_id.split(":")
    assert (prefix, name, len(digest)) == ("sam2", video_dir.name, 12)


def test_encode_predict_shapes_order_and_determinism(video_segmenter) -> None:
    image = _frames(1)[0]
    embedding = video_segmenter.encode(image)
    assert (embedding.height, embedding.width) == (90, 160)
    assert [embedding.arrays[f"feat{i}"].shape for i in range(3)] == [
        (16, SIZE // 4, SIZE // 4), (32, SIZE // 8, SIZE // 8), (128, SIZE // 16, SIZE // 16)]
    points, labels = np.array([[50.0, 40.0], [140.0, 80.0]]), np.array([1, 0])
    first = video_segmenter.predict(embedding, points, labels)
    assert len(first) == 3
    assert all(c.mask.dtype == bool and c.mask.shape == (90, 160) for c in first)
    scores = [c.score for c in first]
    assert scores == sorted(scores, reverse=True) and all(0 <= s <= 1 for s in scores)
    again = video_segmenter.predict(embedding, points, labels)
    assert all(np.array_equal(a.mask, b.mask) and a.score == b.score for a, b in zip(first, again))


def test_embedding_round_trip_gives_same_masks(video_segmenter) -> None:
    embedding = video_segmenter.encode(_frames(1)[0])
    restored = Embedding.from_bytes(embedding.to_bytes())
    points, labels = np.array([[60.0, 30.0]]), np.array([1])
    box = (20.0, 10.0, 120.0, 70.0)
    for kwargs in ({}, {"box": box}, {"prev_mask": np.ones((90, 160), bool)}):
        a = video_segmenter.predict(embedding, points, labels, **kwargs)
        b = video_segmenter.predict(restored, points, labels, **kwargs)
        assert all(np.array_equal(x.mask, y.mask) and x.score == y.score for x, y in zip(a, b))


def test_box_only_prompt(video_segmenter) -> None:
    embedding = video_segmenter.encode(_frames(1)[0])
    out = video_segmenter.predict(embedding, np.zeros((0, 2)), np.zeros(0, int), box=(20, 10, 120, 70))
    assert len(out) == 3 and out[0].mask.shape == (90, 160)


def test_video_propagation(video_segmenter) -> None:
    frames = _frames(4)
    mask = np.zeros((90, 160), bool)
    mask[20:60, 30:80] = True
    seen: list[float] = []
    out = video_segmenter.propagate(frames, mask, progress=seen.append)
    assert len(out) == 3 and all(m.dtype == bool and m.shape == (90, 160) for m in out)
    assert seen[-1] == pytest.approx(1.0) and seen == sorted(seen)
    again = video_segmenter.propagate(frames, mask)
    assert all(np.array_equal(a, b) for a, b in zip(out, again))


def test_image_only_checkpoint_serves_clicks_and_falls_back_to_flow(image_dir: Path) -> None:
    segmenter = make_segmenter("sam2", model_path=image_dir)
    frames = _frames(3)
    out = segmenter.predict(segmenter.encode(frames[0]), np.array([[50.0, 40.0]]), np.array([1]))
    assert len(out) == 3
    mask = np.zeros((90, 160), bool)
    mask[20:60, 30:80] = True
    moved = segmenter.propagate(frames, mask)
    assert len(moved) == 2
    truth = np.zeros_like(mask)
    truth[20:60, 40:90] = True
    assert (moved[-1] & truth).sum() / (moved[-1] | truth).sum() > 0.8


def test_embedding_of_another_model_is_refused(video_segmenter, image_dir: Path) -> None:
    other = make_segmenter("sam2", model_path=image_dir)
    embedding = other.encode(_frames(1)[0])
    with pytest.raises(SegmentError, match="embedding made by"):
        video_segmenter.predict(embedding, np.array([[5.0, 5.0]]), np.array([1]))
    classical = make_segmenter("classical").encode(_frames(1)[0])
    with pytest.raises(SegmentError):
        video_segmenter.predict(classical, np.array([[5.0, 5.0]]), np.array([1]))


def test_bad_model_paths(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="needs sam2_model_path"):
        make_segmenter("sam2")
    with pytest.raises(ValueError, match="not a directory"):
        make_segmenter("sam2", model_path=tmp_path / "missing")
    with pytest.raises(ValueError, match="not a SAM2 checkpoint"):
        make_segmenter("sam2", model_path=tmp_path)
    (tmp_path / "config.json").write_text(json.dumps({"model_type": "bert"}))
    with pytest.raises(ValueError, match="not sam2"):
        make_segmenter("sam2", model_path=tmp_path)
