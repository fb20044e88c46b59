"""The embedded heuristic backend and the backend registry."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from annotation.vlm import PROMPT_VERSION, PrefilterBackend, answered_questions, make_backend
from dataset.synthetic import read_video, render_video, write_synthetic_dataset
from dataset.synthetic.defects import blur, caption


@pytest.fixture(scope="module")
def sharp() -> np.ndarray:
    return render_video(0, n_frames=2, width=320, height=180).frames[0].left


def test_sharp_clean_frame_goes_to_a_curator_with_its_figures(sharp: np.ndarray) -> None:
    backend = make_backend("heuristic")
    [verdict] = backend.classify([sharp])
    assert verdict.parsed and verdict.error is None
    assert verdict.keep is None and verdict.reason.startswith("undecided")
    assert verdict.answers is not None
    assert verdict.answers[8] is False  # not blurry
    assert verdict.answers[6] is False and verdict.answers[7] is False  # no text found
    assert [verdict.answers[i] for i in (0, 1, 2, 3, 4, 5, 9, 10, 11)] == [None] * 9
    assert verdict.raw == "?,?,?,?,?,?,no,no,no,?,?,?"
    measured = {"laplacian_var", "laplacian_var_p90", "caption_band_fraction", "brightness", "contrast"}
    assert measured <= set(verdict.metrics)


def test_blurred_frame_is_rejected_as_too_blurry(sharp: np.ndarray) -> None:
    [verdict] = make_backend("heuristic").classify([blur(sharp)])
    assert verdict.answers is not None and verdict.answers[8] is True
    assert verdict.keep is False and "Q9" in verdict.reason
    assert verdict.metrics["laplacian_var_p90"] < 60


def test_caption_band_is_rejected_as_excessive_captions(sharp: np.ndarray) -> None:
    [verdict] = make_backend("heuristic").classify([caption(sharp)])
    assert verdict.answers is not None
    assert verdict.answers[6] is True and verdict.answers[7] is False
    assert verdict.keep is False and "Q7" in verdict.reason
    assert verdict.metrics["caption_band_fraction"] >= 0.05


def test_corner_watermark_is_noticed_but_does_not_reject() -> None:
    frame = render_video(1, n_frames=2, width=640, height=360).frames[0].left.copy()
    cv2.putText(frame, "@logo.tv", (512, 29), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    [verdict] = make_backend("heuristic").classify([frame])
    assert verdict.answers is not None and verdict.answers[7] is True
    assert verdict.keep is None
    assert verdict.metrics["corner_text_count"] >= 1


def test_bad_images_fail_alone_in_order(sharp: np.ndarray) -> None:
    verdicts = make_backend("heuristic").classify([sharp, np.zeros((4, 4), np.float32), sharp[..., :2]])
    assert verdicts[0].error is None
    assert verdicts[1].error is not None and "RGB uint8" in verdicts[1].error
    assert verdicts[2].error is not None and not verdicts[2].parsed and verdicts[2].keep is None


def test_registry_builds_the_heuristic_and_explains_bad_choices(tmp_path) -> None:
    backend = make_backend("heuristic")
    assert isinstance(backend, PrefilterBackend)
    assert (backend.name, backend.model_id, backend.prompt_version) == ("heuristic", "heuristic-v1", PROMPT_VERSION)
    with pytest.raises(ValueError, match="unknown VLM backend 'gpt'"):
        make_backend("gpt")
    with pytest.raises(ValueError, match="needs a model path"):
        make_backend("transformers")
    with pytest.raises(ValueError, match="base URL"):
        make_backend("openai", model="m")
    with pytest.raises(ValueError, match="model name"):
        make_backend("openai", base_url="http://127.0.0.1:1/v1")


def test_registry_says_which_questions_a_backend_answers() -> None:
    assert answered_questions("heuristic") == (7, 8, 9)
    assert answered_questions("openai") == answered_questions("transformers") == tuple(range(1, 13))


def test_demo_videos_end_with_frames_the_heuristic_drops(tmp_path) -> None:  # type: ignore[no-untyped-def]
    [path] = write_synthetic_dataset(tmp_path, videos=1, n_frames=1, width=320, height=180, defects=True)
    scene = json.loads((path / "scene.json").read_text())
    assert [f.get("defect") for f in scene["frames"]] == [None, "caption", "blur"]
    verdicts = make_backend("heuristic").classify([f.left for f in read_video(path).frames])
    assert [v.keep for v in verdicts] == [None, False, False]
    assert "Q7" in verdicts[1].reason and "Q9" in verdicts[2].reason
