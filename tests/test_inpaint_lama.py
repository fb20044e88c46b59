"""LaMa hole filling (annotation/inpaint) through a real TorchScript file, alone and as the
geometry's hole filler, and the configured choice (dataset/services/inpaint.py)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from annotation.inpaint import Inpainter, InpainterError, make_inpainter
from core.geometry import InpaintError, inpaint_holes, synthesize_right_view
from dataset.services.inpaint import HOLE_FILLERS, hole_filler

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def mean_fill_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A TorchScript stand-in for big-lama.pt: fills masked pixels with the unmasked mean."""

    class MeanFill(torch.nn.Module):
        def forward(self, image: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
            assert image.shape[2] % 8 == 0 and image.shape[3] % 8 == 0
            known = 1.0 - mask
            mean = (image * known).sum(dim=(2, 3), keepdim=True) / known.sum(dim=(2, 3), keepdim=True)
            return image * known + mean * mask

    path = tmp_path_factory.mktemp("lama") / "big-lama.pt"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # TorchScript is what big-lama.pt is
        torch.jit.script(MeanFill()).save(str(path))
    return path


def test_lama_backend_runs_a_torchscript_model(mean_fill_model: Path) -> None:
    lama = make_inpainter("lama", model_path=mean_fill_model)
    assert isinstance(lama, Inpainter) and lama.model_id.startswith("lama:big-lama.pt:")
    image = np.zeros((13, 21, 3), dtype=np.uint8)  # not multiples of 8: padded and cropped
    image[..., 0] = 100
    image[..., 2] = 40
    holes = np.zeros((13, 21), dtype=bool)
    holes[4:9, 5:12] = True
    image[holes] = 0
    filled = lama.inpaint(image, holes)
    np.testing.assert_array_equal(filled[~holes], image[~holes])
    # The mean over the padded frame (reflect padding repeats known pixels) is the colour.
    np.testing.assert_array_equal(filled[holes], np.tile([100, 0, 40], (int(holes.sum()), 1)))
    np.testing.assert_array_equal(inpaint_holes(image, holes, lama.inpaint), filled)
    gray = lama.inpaint(image[..., 0], holes)
    assert gray.shape == (13, 21) and (gray[holes] == 100).all()


def test_lama_right_view_and_bad_models(mean_fill_model: Path, tmp_path: Path) -> None:
    left = np.full((16, 40, 3), 77, dtype=np.uint8)
    disparity = np.full((16, 40), 3.0)
    result = synthesize_right_view(left, disparity, scale=1.0, inpaint=hole_filler("lama", mean_fill_model))
    assert result.holes[:, -3:].all()
    assert (result.image == 77).all()
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a model")
    for kwargs, message in [({"model_path": junk}, "not a TorchScript model"),
                            ({"model_path": tmp_path / "none.pt"}, "does not exist"),
                            ({}, "needs a TorchScript model path"),
                            ({"model_path": mean_fill_model, "device": "toaster"}, "bad torch device")]:
        with pytest.raises(InpainterError, match=message):
            make_inpainter("lama", **kwargs)  # type: ignore[arg-type]
    with pytest.raises(InpainterError, match="unknown inpainting backend 'telea'"):
        make_inpainter("telea")
    with pytest.raises(InpainterError, match="holes must be bool"):
        make_inpainter("lama", model_path=mean_fill_model).inpaint(left, np.zeros((2, 2), bool))


def test_the_configured_choice(mean_fill_model: Path) -> None:
    assert HOLE_FILLERS == ("telea", "ns", "none", "lama")
    assert hole_filler("telea") == "telea" and hole_filler("none") == "none"
    assert callable(hole_filler("lama", mean_fill_model))
    with pytest.raises(InpaintError, match="unknown inpainting method 'magic'"):
        hole_filler("magic")


def test_a_filler_that_breaks_the_contract_is_refused() -> None:
    image = np.zeros((4, 5, 3), np.uint8)
    holes = np.zeros((4, 5), bool)
    holes[1, 1] = True
    with pytest.raises(InpaintError, match="hole filler returned float64"):
        inpaint_holes(image, holes, lambda img, _holes: img.astype(np.float64))
    # Whatever a filler returns outside the holes is not used.
    out = inpaint_holes(image, holes, lambda img, _holes: np.full_like(img, 9))
    assert out[1, 1].tolist() == [9, 9, 9] and out.sum() == 27
