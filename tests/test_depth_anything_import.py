"""Depth Anything V2's original ``.pth`` files: `checkpoints import --from depth-anything-v2` converts one
to a transformers directory registered as ``imported:NAME``, and `depth --checkpoint imported:NAME`
returns what the original code's ``infer_image(image, 518)`` does (golden fixture:
tests/fixtures/depth_anything/, made by its make_golden.py from seeded weights)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")
pytest.importorskip("transformers")

from annotation.depth import DepthError  # noqa: E402
from annotation.depth.depth_anything import DepthAnythingBackend, upsample  # noqa: E402
from annotation.depth.depth_anything_import import (  # noqa: E402
    IMPORT_FILE,
    NotDepthAnything,
    convert,
    infer_architecture,
    to_transformers,
)
from core.formats import read_pfm, read_rgb  # noqa: E402
from tests.depth_anything_golden import fixture_state, import_golden, load_fixture  # noqa: E402
from webapp.cli import main  # noqa: E402

QKV_TENSORS = 2 * 12  # vits: each block's fused qkv weight and bias become three tensors each


def _cli(home: Path, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["--data-dir", str(home), *args])


@pytest.fixture(scope="module")
def fixture() -> dict:
    return load_fixture("vits")


@pytest.fixture(scope="module")
def state(fixture: dict) -> dict[str, torch.Tensor]:
    return fixture_state(fixture)


@pytest.fixture(scope="module")
def imported(tmp_path_factory: pytest.TempPathFactory, state: dict[str, torch.Tensor]) -> tuple[Path, dict]:
    """A workspace with the fixture's weights imported from an original-layout file, and the answer."""
    home = tmp_path_factory.mktemp("da-import") / "ws"
    return home, import_golden(home, "da-s", load_fixture("vits"), state)


@pytest.mark.slow
def test_imported_original_file_infers_what_the_original_code_does(imported, fixture: dict, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    home, doc = imported
    assert doc["checkpoint"] == "imported:da-s"
    assert doc["architecture"] == {"encoder": "vits", "embed_dim": 384, "depth": 12, "heads": 6,
                                   "out_indices": [3, 6, 9, 12], "neck_hidden_sizes": [48, 96, 192, 384],
                                   "fusion_hidden_size": 64, "head_hidden_size": 32, "swiglu": False}
    assert doc["tensors_in_file"] == len(fixture["keys"]) == 239
    assert doc["keys_loaded"] == doc["tensors_in_file"] + 2 * QKV_TENSORS  # every tensor placed, none invented
    folder = home / "checkpoints" / "imported" / "da-s"
    assert {p.name for p in folder.iterdir()} == {"config.json", "model.safetensors", IMPORT_FILE}
    assert json.loads((folder / IMPORT_FILE).read_text())["pipeline"] == "original"

    reference = fixture["depth"]
    image = read_rgb(fixture["image"])
    assert reference.shape == image.shape[:2] == (61, 83) and image.shape[0] % 14 and image.shape[1] % 14
    out = tmp_path / "depth.pfm"
    result = _cli(home, "depth", str(fixture["image"]), "--checkpoint", "imported:da-s", "--out", str(out))
    assert result.exit_code == 0, result.output
    ours = read_pfm(out)
    tolerance = 1e-3 * float(np.abs(reference).max())
    assert ours.shape == reference.shape and ours.dtype == np.float32
    assert np.abs(ours - reference).max() <= tolerance, f"off by up to {np.abs(ours - reference).max():.2e}"
    assert float(reference.std()) > 100 * tolerance  # a varied map, not a constant the check would pass trivially

    # Each of the original's steps matters at this tolerance: resizing the output back without
    # aligned corners, or interpolating position embeddings as transformers does, fails it.
    backend = DepthAnythingBackend(folder)
    assert backend.original
    network = backend.network_output(image)
    assert np.array_equal(upsample(network, 61, 83), ours)
    assert np.abs(upsample(network, 61, 83, align_corners=False) - reference).max() > 10 * tolerance
    with pytest.raises(DepthError, match="an aspect ratio beyond 8:1 is not supported"):
        backend.estimate(np.zeros((10, 90, 3), np.uint8))
    del backend.model.backbone.embeddings.interpolate_pos_encoding  # back to transformers' own
    plain = upsample(backend.network_output(image), 61, 83)
    assert np.abs(plain - reference).max() > 10 * tolerance


@pytest.mark.slow
def test_imported_depth_models_and_stereo_checkpoints_keep_to_their_commands(imported, fixture: dict,  # type: ignore[no-untyped-def]
                                                                              tmp_path: Path) -> None:
    home, _ = imported
    image = str(fixture["image"])
    stereo = _cli(home, "predict", image, image, "--checkpoint", "imported:da-s", "--out", str(tmp_path / "a.pfm"))
    assert stereo.exit_code == 1 and "imported:da-s is an imported depth model" in stereo.output
    missing = _cli(home, "depth", image, "--checkpoint", "imported:other", "--out", str(tmp_path / "b.pfm"))
    assert missing.exit_code == 1 and "no imported depth model 'other' (imported: imported:da-s;" in missing.output
    run = _cli(home, "depth", image, "--checkpoint", "3:best", "--out", str(tmp_path / "c.pfm"))
    assert run.exit_code == 1 and "names a run's checkpoint, not a depth model" in run.output
    taken = tmp_path / "x.pth"
    taken.write_bytes(b"")
    clash = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(taken), "--name", "da-s")
    assert clash.exit_code == 1 and "imported:da-s is taken by another kind of checkpoint" in clash.output


def test_depth_runs_a_transformers_directory_with_its_own_processor(tmp_path: Path, fixture: dict) -> None:
    """A directory saved by transformers (no import record) keeps the backend's processor pipeline."""
    import transformers

    backbone = transformers.Dinov2Config(hidden_size=32, num_hidden_layers=4, num_attention_heads=2,
                                         intermediate_size=64, patch_size=14, image_size=70,
                                         out_indices=[1, 2, 3, 4], reshape_hidden_states=False)
    config = transformers.DepthAnythingConfig(backbone_config=backbone, reassemble_hidden_size=32,
                                              neck_hidden_sizes=[8, 16, 32, 32], fusion_hidden_size=16,
                                              head_hidden_size=8, patch_size=14)
    torch.manual_seed(0)
    transformers.DepthAnythingForDepthEstimation(config).save_pretrained(tmp_path / "tiny")
    out = tmp_path / "d.pfm"
    result = CliRunner().invoke(main, ["depth", str(fixture["image"]), "--checkpoint", str(tmp_path / "tiny"),
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    backend = DepthAnythingBackend(tmp_path / "tiny")
    assert not backend.original
    assert np.array_equal(read_pfm(out), backend.estimate(read_rgb(fixture["image"])))
    bad = CliRunner().invoke(main, ["depth", str(fixture["image"]), "--checkpoint", str(tmp_path / "tiny"),
                                    "--out", str(tmp_path / "d.png")])
    assert bad.exit_code == 2 and "must end in .pfm" in bad.output


def _shapes(width: int, blocks: int, *, swiglu: bool = False) -> dict[str, torch.Tensor]:
    """Just the tensors infer_architecture reads, for an encoder ``width`` wide with ``blocks`` blocks."""
    state = {"pretrained.patch_embed.proj.weight": torch.empty(width, 3, 14, 14),
             "pretrained.pos_embed": torch.empty(1, 1370, width), "pretrained.cls_token": torch.empty(1, 1, width),
             "depth_head.scratch.layer1_rn.weight": torch.empty(64, 48, 3, 3),
             "depth_head.scratch.output_conv2.0.weight": torch.empty(32, 32, 3, 3)}
    state.update({f"depth_head.projects.{i}.weight": torch.empty(48 << i, width, 1, 1) for i in range(4)})
    state.update({f"pretrained.blocks.{i}.norm1.weight": torch.empty(width) for i in range(blocks)})
    if swiglu:
        state["pretrained.blocks.0.mlp.w12.weight"] = torch.empty(2, width)
    return state


@pytest.mark.parametrize(("width", "blocks", "encoder", "heads", "taps"), [
    (384, 12, "vits", 6, [3, 6, 9, 12]), (768, 12, "vitb", 12, [3, 6, 9, 12]),
    (1024, 24, "vitl", 16, [5, 12, 18, 24]), (1536, 40, "vitg", 24, [10, 20, 30, 40])])
def test_the_encoder_is_read_from_the_tensors(width: int, blocks: int, encoder: str, heads: int,
                                              taps: list[int]) -> None:
    arch = infer_architecture(_shapes(width, blocks, swiglu=encoder == "vitg"))
    assert (arch["encoder"], arch["heads"], arch["out_indices"], arch["swiglu"]) == (encoder, heads, taps,
                                                                                     encoder == "vitg")
    assert arch["neck_hidden_sizes"] == [48, 96, 192, 384] and arch["fusion_hidden_size"] == 64


def test_fused_matrices_split_as_the_original_uses_them() -> None:
    """qkv rows are [q; k; v]; SwiGLU's w12 rows are [gate; up] (silu of the first half times the second)."""
    qkv, w12 = torch.randn(9, 3), torch.randn(8, 3)
    mapped, unplaced = to_transformers({"pretrained.blocks.0.attn.qkv.weight": qkv,
                                        "pretrained.blocks.0.mlp.w12.weight": w12,
                                        "pretrained.blocks.0.mlp.w3.bias": torch.zeros(3),
                                        "depth_head.scratch.refinenet4.out_conv.bias": torch.zeros(2),
                                        "depth_head.scratch.stem.weight": torch.zeros(1)}, {"embed_dim": 3})
    layer = "backbone.encoder.layer.0."
    assert [mapped[f"{layer}attention.{n}_proj.weight"].tolist() for n in "qkv"] == [qkv[:3].tolist(),
                                                                                      qkv[3:6].tolist(),
                                                                                      qkv[6:].tolist()]
    assert torch.equal(mapped[f"{layer}mlp.gate_proj.weight"], w12[:4])
    assert torch.equal(mapped[f"{layer}mlp.up_proj.weight"], w12[4:])
    assert f"{layer}mlp.down_proj.bias" in mapped
    assert "neck.fusion_stage.layers.0.projection.bias" in mapped  # refinenet4 runs first
    assert unplaced == ["depth_head.scratch.stem.weight"]


@pytest.mark.parametrize(("edit", "message"), [
    (lambda s: _shapes(512, 12), "an encoder 512 wide with 12 blocks is none of Depth Anything V2's"),
    (lambda s: _shapes(384, 13), "an encoder 384 wide with 13 blocks is none of Depth Anything V2's"),
    (lambda s: {k: v for k, v in s.items() if k != "pretrained.pos_embed"},
     "not a Depth Anything V2 checkpoint: no pretrained.pos_embed"),
    (lambda s: {**s, "depth_head.readout_projects.0.0.weight": torch.zeros(1)}, "class-token readouts"),
    (lambda s: {**s, "depth_head.scratch.refinenet1.resConfUnit1.bn1.weight": torch.zeros(1)},
     "batch-normed fusion blocks"),
    (lambda s: {**s, "pretrained.pos_embed": torch.zeros(1, 257, 384)}, "holds 256 patch positions"),
    (lambda s: {**s, "pretrained.blocks.0.attn.extra": torch.zeros(1)},
     "unknown pretrained.blocks.0.attn.extra"),
    (lambda s: {k: v for k, v in s.items() if k != "depth_head.scratch.output_conv1.bias"},
     "missing head.conv1.bias"),
    (lambda s: {**s, "depth_head.projects.0.bias": torch.zeros(7)},
     r"neck.reassemble_stage.layers.0.projection.bias would have shape (7,)"),
    (lambda s: {**s, "pretrained.cls_token": [1, 2]}, "not a state dict of tensors: pretrained.cls_token is a list"),
])
def test_files_whose_tensors_do_not_settle_the_model_are_refused(state, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(NotDepthAnything, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        convert(edit(state))
    assert "\n" not in str(info.value)


def test_the_cli_refuses_in_one_line_and_registers_nothing(tmp_path: Path, state) -> None:  # type: ignore[no-untyped-def]
    home = tmp_path / "ws"
    home.mkdir()
    small = {key: value for key, value in state.items() if not key.startswith("pretrained.blocks.11.")}
    odd, metric, text = tmp_path / "odd.pth", tmp_path / "depth_anything_v2_metric_hypersim_vits.pth", tmp_path / "t.pth"
    torch.save(small, odd)
    torch.save({"x": torch.zeros(1)}, metric)
    text.write_text("not a checkpoint")
    cases = [(odd, "an encoder 384 wide with 11 blocks is none of Depth Anything V2's"),
             (metric, "looks like a metric-depth file"),
             (text, "t.pth is not a readable checkpoint")]
    for path, message in cases:
        result = _cli(home, "checkpoints", "import", "--from", "depth-anything-v2", str(path))
        assert result.exit_code == 1 and message in result.output, result.output
        assert result.output.count("\n") == 1 and "Traceback" not in result.output
    folder = home / "checkpoints" / "imported"
    assert not folder.exists() or not any(folder.iterdir())
