"""An imported Depth Anything V2 model (`checkpoints import --from depth-anything-v2`) serves where a
depth directory is configured: the setting ``depth_model_path = "imported:NAME"`` makes generation's
depth backend run it, and the ``paper`` preset's mono branch loads the imported directory
(docs/depth-anything.md, "Serving generation and the paper preset")."""

from __future__ import annotations

import json
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from dataset.imported import depth_model_dir
from dataset.services.errors import FieldError, NotFound

IMPORTED = Path("checkpoints") / "imported"


def _fake_import(home: Path, name: str) -> Path:
    """A directory where an imported depth model lives (what resolving looks for, no weights)."""
    folder = home / IMPORTED / name
    folder.mkdir(parents=True)
    (folder / "config.json").write_text("{}")
    return folder


def test_the_setting_names_an_import_and_nothing_through_a_link(tmp_path: Path) -> None:
    home = tmp_path / "ws"
    folder = _fake_import(home, "da-s")
    elsewhere = _fake_import(tmp_path / "other", "da-b")
    os.symlink(elsewhere, home / IMPORTED / "da-b")
    settings = SimpleNamespace(home=home, depth_model_path=Path("imported:da-s"))
    assert depth_model_dir(settings) == folder
    assert depth_model_dir(SimpleNamespace(home=home, depth_model_path=tmp_path / "dir")) == tmp_path / "dir"
    assert depth_model_dir(SimpleNamespace(home=home, depth_model_path=None)) is None
    for name in ("da-b", "missing"):  # a link is not the workspace's own import
        with pytest.raises(NotFound) as refused:
            depth_model_dir(SimpleNamespace(home=home, depth_model_path=f"imported:{name}"))
        message = str(refused.value)
        assert message.startswith(f"depth_model_path imported:{name}: no imported depth model {name!r} "
                                  "(imported: imported:da-s;") and "\n" not in message
        assert "checkpoints import --from depth-anything-v2 FILE" in message


def test_an_unknown_import_blocks_samples_and_the_train_worker(tmp_path: Path) -> None:
    from dataset.services.sample_blockers import sample_blocker
    from model.presets import load_preset
    from model.runs.handlers import preflight
    from model.runs.schema import backbone_dirs
    from tests.conftest import make_settings

    home = tmp_path / "ws"
    _fake_import(home, "da-s")
    (tmp_path / "qwen").mkdir()
    settings = make_settings(home, depth_backend="depth-anything-v2", depth_model_path="imported:nope",
                             vlm_model_path=str(tmp_path / "qwen"))
    assert str(settings.depth_model_path) == "imported:nope"  # a name, kept as written
    blocker = sample_blocker(settings, None)
    assert blocker is not None and blocker.startswith("depth_model_path imported:nope: no imported depth model")
    with pytest.raises(FieldError, match="depth_model_path imported:nope: no imported depth model 'nope'") as refused:
        preflight(load_preset("paper"), {"nproc": 1, "devices": "cpu"}, tmp_path, settings)
    assert refused.value.field == "preset"
    known = make_settings(home, depth_backend="depth-anything-v2", depth_model_path="imported:da-s",
                          vlm_model_path=str(tmp_path / "qwen"))
    assert sample_blocker(known, None) is None
    # what the launch's memory estimate, other nodes and the engine get: this workspace's directory
    assert backbone_dirs(load_preset("paper"), known) == {"mono_model_path": str(home / IMPORTED / "da-s"),
                                                          "vlm_model_path": str(tmp_path / "qwen")}


# --- the golden vits fixture, imported as a user imports it -------------------------------------------

@pytest.fixture(scope="module")
def golden() -> dict:
    pytest.importorskip("transformers")
    from tests.depth_anything_golden import load_fixture

    return load_fixture("vits")


@pytest.fixture(scope="module")
def imported_home(tmp_path_factory: pytest.TempPathFactory, golden: dict) -> Path:
    """A workspace with the golden vits weights imported as ``imported:da-s``."""
    from tests.depth_anything_golden import import_golden

    home = tmp_path_factory.mktemp("da-serve") / "ws"
    import_golden(home, "da-s", golden)
    return home


@pytest.fixture
def settings(imported_home: Path, migrated_sqlite: Path):  # type: ignore[no-untyped-def]
    """The runtime's settings (conftest's ``runtime``): generation's depth backend is the import."""
    from tests.conftest import make_settings, migrate_copying

    write = {"depth_backend": "depth-anything-v2", "depth_model_path": "imported:da-s"}
    (imported_home / "illusion-studio.toml").write_text("".join(f"{k} = {json.dumps(v)}\n" for k, v in write.items()))
    s = make_settings(imported_home)
    migrate_copying(s.database_url, migrated_sqlite)
    return s


@pytest.mark.slow
def test_generation_runs_the_import_the_depth_command_runs(runtime, imported_home: Path, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from click.testing import CliRunner
    from sqlalchemy import select

    from core.formats import read_pfm, write_rgb
    from dataset.samples import load_outputs
    from dataset.tables import Job, Sample
    from tests.test_generate import generate_all, prepare
    from webapp.cli import main

    assert str(runtime.settings.depth_model_path) == "imported:da-s"
    prepare(runtime, tmp_path, n_frames=1)
    generate_all(runtime)
    with runtime.sessions() as s:
        sample = s.scalar(select(Sample))
        assert sample is not None, [job.error for job in s.scalars(select(Job))]
        provenance = dict(sample.provenance)
    assert provenance["depth_backend"] == "depth-anything-v2" and provenance["simulated"] is False
    assert provenance["depth_model_id"].startswith("depth-anything-v2:da-s:")
    out = load_outputs(runtime.media, sample.files)
    left, mono = out["left"], out["disparity_mono"]
    # The same image, lossless, through the command: both run DepthAnythingBackend.estimate on the
    # frame as stored (no resize between them; each resizes to the network's input and back itself).
    image = tmp_path / "left.png"
    write_rgb(image, left)
    for extra in (["--checkpoint", "imported:da-s"], []):  # named, and the workspace's own setting
        pfm = tmp_path / f"depth{len(extra)}.pfm"
        result = CliRunner().invoke(main, ["--data-dir", str(imported_home), "depth", str(image), "--out", str(pfm),
                                           *extra])
        assert result.exit_code == 0, result.output
        reference = read_pfm(pfm)
        assert reference.shape == mono.shape == left.shape[:2]
        assert np.abs(mono.astype(np.float32) - reference).max() <= 1e-6 * float(np.abs(reference).max())
    assert float(reference.std()) > 1e-3 * float(np.abs(reference).max())  # a varied map: the check can fail


@pytest.mark.slow
def test_the_paper_mono_branch_loads_the_import_with_its_original_positions(imported_home: Path) -> None:
    torch = pytest.importorskip("torch")
    pytest.importorskip("peft")
    import torch.nn.functional as F

    from annotation.depth.depth_anything import DepthAnythingBackend
    from model.network import FusionNetwork
    from model.presets import load_preset
    from tests.test_model_paper import TINY
    from tests.test_vlm_transformers import save_tiny_qwen2_vl

    folder = depth_model_dir(SimpleNamespace(home=imported_home, depth_model_path="imported:da-s"))
    assert folder == imported_home / IMPORTED / "da-s"
    vlm = save_tiny_qwen2_vl(imported_home.parent / "qwen")
    config = load_preset("paper", {**TINY, "mono_model_path": str(folder), "vlm_model_path": str(vlm)})
    torch.manual_seed(0)
    network = FusionNetwork(config.model).eval()
    assert network.mono.original_positions
    seen: list[torch.Tensor] = []
    network.mono.backbone.register_forward_pre_hook(lambda _m, _a, kw: seen.append(kw["pixel_values"]),
                                                    with_kwargs=True)
    left = torch.rand(1, 3, 64, 96) * 255
    with torch.no_grad():
        out = network(left, torch.roll(left, -2, dims=3), None, iters=2)
    assert out.disparity.shape == out.mono.shape == (1, 1, 64, 96)
    assert torch.isfinite(out.disparity).all()
    # The branch's estimate is the import's network as `depth` runs it (original position grid) on
    # the branch's own input (long side to mono_input_size = 70 px: 42x70).
    [pixels] = seen
    assert tuple(pixels.shape[2:]) == (42, 70)
    backend = DepthAnythingBackend(folder)
    with torch.no_grad():
        reference = backend.model(pixel_values=pixels).predicted_depth.unsqueeze(1)
        del backend.model.backbone.embeddings.interpolate_pos_encoding  # transformers' own grid
        plain = backend.model(pixel_values=pixels).predicted_depth.unsqueeze(1)
    expected, transformers_grid = (F.interpolate(x, (64, 96), mode="bilinear", align_corners=False)
                                   for x in (reference, plain))
    tolerance = 1e-5 * float(expected.abs().max())
    assert (out.mono - expected).abs().max() <= tolerance
    assert (out.mono - transformers_grid).abs().max() > 100 * tolerance
