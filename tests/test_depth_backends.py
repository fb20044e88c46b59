"""Monocular depth backends: Depth Anything V2 end to end on a tiny randomly initialised checkpoint
saved to a temp dir (the real from_pretrained load, preprocessing, inference, post-processing),
the registry's errors, and the precomputed formats."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from annotation.depth import DepthBackend, DepthError, make_depth_backend
from dataset.synthetic import render_video

torch = pytest.importorskip("torch")
transformers = pytest.importorskip("transformers")

SIZE = 70  # processor target side (5 patches of 14)


def _save_tiny(path: Path, *, processor: bool = True, **config: object) -> Path:
    """A tiny Depth Anything (DINOv2 backbone: 4 layers, 32 wide, patch 14) saved like a released
    checkpoint, with a processor config targeting SIZE px when ``processor``."""
    torch.manual_seed(0)
    backbone = transformers.Dinov2Config(hidden_size=32, num_hidden_layers=4, num_attention_heads=2,
                                         intermediate_size=64, patch_size=14, image_size=SIZE,
                                         out_indices=[1, 2, 3, 4], reshape_hidden_states=False)
    model_config = transformers.DepthAnythingConfig(backbone_config=backbone, reassemble_hidden_size=32,
                                                    neck_hidden_sizes=[8, 16, 32, 32], fusion_hidden_size=16,
                                                    head_hidden_size=8, patch_size=14, **config)
    transformers.DepthAnythingForDepthEstimation(model_config).save_pretrained(path)
    if processor:
        transformers.DPTImageProcessorPil(size={"height": SIZE, "width": SIZE}, keep_aspect_ratio=True,
                                          ensure_multiple_of=14, resample=3).save_pretrained(path)
    return path


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _save_tiny(tmp_path_factory.mktemp("da-tiny"))


@pytest.fixture(scope="module")
def frame() -> np.ndarray:
    return render_video(1, n_frames=1, width=160, height=90).frames[0].left


def _input_shapes(backend: DepthBackend) -> list[tuple[int, ...]]:
    """Records the pixel_values shape of every forward call of the backend's model."""
    shapes: list[tuple[int, ...]] = []
    backend.model.register_forward_pre_hook(  # type: ignore[attr-defined]
        lambda _m, _a, kw: shapes.append(tuple(kw["pixel_values"].shape)), with_kwargs=True)
    return shapes


def test_depth_anything_estimates_a_deterministic_map_at_input_size(model_dir: Path, frame: np.ndarray) -> None:
    backend = make_depth_backend("depth-anything-v2", model_path=model_dir)
    assert isinstance(backend, DepthBackend) and backend.name == "depth-anything-v2"
    assert backend.model_id.startswith(f"depth-anything-v2:{model_dir.name}:")
    shapes = _input_shapes(backend)
    disparity = backend.estimate(frame)
    assert disparity.shape == (90, 160) and disparity.dtype == np.float32
    assert np.isfinite(disparity).all()
    # keep-aspect resize to the processor's 70 px target, sides multiples of the 14 px patch
    assert shapes == [(1, 3, 70, 126)]
    assert np.array_equal(disparity, backend.estimate(frame))
    again = make_depth_backend("depth-anything-v2", model_path=model_dir)
    assert again.model_id == backend.model_id
    assert np.array_equal(disparity, again.estimate(frame))
    with pytest.raises(DepthError, match="RGB uint8 HxWx3"):
        backend.estimate(frame[..., 0])


def test_without_a_processor_config_the_released_settings_apply(tmp_path: Path, frame: np.ndarray) -> None:
    backend = make_depth_backend("depth-anything-v2", model_path=_save_tiny(tmp_path / "bare", processor=False))
    shapes = _input_shapes(backend)
    assert backend.estimate(frame).shape == (90, 160)
    # 518 px target, aspect kept by scaling as little as possible (160 → 518 wide, so 90 → 291.4
    # high), then sides rounded to multiples of 14
    assert shapes == [(1, 3, 294, 518)]


def test_registry_refuses_with_one_line(tmp_path: Path, model_dir: Path) -> None:
    cases = [(("sam2",), {}, "unknown depth backend 'sam2'"),
             (("depth-anything-v2",), {}, "needs depth_model_path"),
             (("depth-anything-v2",), {"model_path": tmp_path / "nope"}, "is not a directory"),
             (("depth-anything-v2",), {"model_path": tmp_path}, "not a Depth Anything checkpoint"),
             (("depth-anything-v2",), {"model_path": model_dir, "device": "toaster"}, "bad torch device")]
    for args, kwargs, message in cases:
        with pytest.raises(ValueError, match=message) as info:
            make_depth_backend(*args, **kwargs)
        assert "\n" not in str(info.value)
    (tmp_path / "config.json").write_text(json.dumps({"model_type": "dpt"}))
    with pytest.raises(ValueError, match="'dpt' model, not depth_anything"):
        make_depth_backend("depth-anything-v2", model_path=tmp_path)
    metric = _save_tiny(tmp_path / "metric", depth_estimation_type="metric", max_depth=20)
    with pytest.raises(ValueError, match="metric-depth checkpoint"):
        make_depth_backend("depth-anything-v2", model_path=metric)


def test_precomputed_backend_has_no_model(frame: np.ndarray) -> None:
    backend = make_depth_backend("precomputed")
    assert isinstance(backend, DepthBackend) and backend.model_id == "precomputed"
    with pytest.raises(DepthError, match="import a disparity with the frame"):
        backend.estimate(frame)
