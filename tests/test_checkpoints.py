"""Opening and naming local checkpoint directories (annotation/checkpoints.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from annotation.checkpoints import fingerprint, open_checkpoint


def _checkpoint(path: Path, model_type: str = "sam2", weights: bytes = b"\0" * 64) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    (path / "config.json").write_text(json.dumps({"model_type": model_type, "hidden_size": 8}))
    (path / "model.safetensors").write_bytes(weights)
    return path


def test_open_names_the_weights_by_directory_and_fingerprint(tmp_path: Path) -> None:
    checkpoint = open_checkpoint(_checkpoint(tmp_path / "tiny"), "SAM2", {"sam2", "sam2_video"})
    assert checkpoint.model_type == "sam2" and checkpoint.config["hidden_size"] == 8
    prefix, name, digest = checkpoint.model_id("sam2").split(":")
    assert (prefix, name, len(digest)) == ("sam2", "tiny", 12) and digest == checkpoint.fingerprint
    assert open_checkpoint(tmp_path / "tiny", "SAM2").fingerprint == digest  # same files, same name


def test_fingerprint_follows_weights_and_configs_not_other_files(tmp_path: Path) -> None:
    path = _checkpoint(tmp_path / "m")
    before = fingerprint(path)
    (path / "README.md").write_text("notes")
    assert fingerprint(path) == before
    (path / "model.safetensors").write_bytes(b"\0" * 65)  # replaced weights
    replaced = fingerprint(path)
    assert replaced != before
    (path / "generation_config.json").write_text(json.dumps({"max_new_tokens": 4}))
    assert fingerprint(path) != replaced
    other = _checkpoint(tmp_path / "n", model_type="sam2_video")
    assert fingerprint(other) != before


@pytest.mark.parametrize(("setup", "message"), [
    (lambda p: None, "not a directory"),
    (lambda p: p.mkdir(), "not a SAM2 checkpoint directory"),
    (lambda p: (p.mkdir(), (p / "config.json").write_text("{")), "not a SAM2 checkpoint directory"),
    (lambda p: (p.mkdir(), (p / "config.json").write_text("{}")), "model_type"),
    (lambda p: (p.mkdir(), (p / "config.json").write_text('{"model_type": 3}')), "must be a string"),
    (lambda p: _checkpoint(p, "bert"), "'bert' model, not sam2 or sam2_video"),
])
def test_bad_directories_are_one_line_errors(tmp_path: Path, setup, message: str) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "ckpt"
    setup(path)
    with pytest.raises(ValueError, match=message) as info:
        open_checkpoint(path, "SAM2", {"sam2", "sam2_video"})
    assert "\n" not in str(info.value)
