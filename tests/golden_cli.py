"""What the golden import tests of the published stereo networks (RAFT-Stereo, Selective-RAFT,
Selective-IGEV, MoCha-Stereo: tests/test_*_import.py) share: the comparison's tolerance, the command line run in a
workspace, an import's accounting of the file's tensors, `predict` on a fixture's pair and the
deliberate bugs of the predictor's path that the comparison must catch."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from core.formats import read_pfm, write_rgb
from model import predictor as predictor_module
from model.checkpoint import load_checkpoint
from model.presets import ModelConfig
from webapp.cli import main

Patch = Callable[[], AbstractContextManager[None]]


def excess(ours: np.ndarray, reference: np.ndarray) -> float:
    """How far the worst pixel lies beyond the tolerance, 1e-3 px + 1e-4·|reference| (≤ 0: within)."""
    return float((np.abs(ours - reference) - (1e-3 + 1e-4 * np.abs(reference))).max())


def cli(home: Path, *args: str):  # type: ignore[no-untyped-def]
    """The command line with ``args`` in the workspace ``home``."""
    return CliRunner().invoke(main, ["--data-dir", str(home), *args])


def predict_cli(home: Path, tmp_path: Path, fixture: dict[str, Any], checkpoint: str, *args: str) -> np.ndarray:
    """`predict` with ``checkpoint`` (and ``args``) on the fixture's pair, written as PNGs under ``tmp_path``."""
    write_rgb(tmp_path / "left.png", fixture["left"])
    write_rgb(tmp_path / "right.png", fixture["right"])
    out = tmp_path / "disparity.pfm"
    result = cli(home, "predict", str(tmp_path / "left.png"), str(tmp_path / "right.png"), "--checkpoint",
                 checkpoint, "--out", str(out), *args)
    assert result.exit_code == 0, result.output
    return read_pfm(out)


def assert_accounted(doc: dict[str, Any], checkpoint: str, counts: tuple[int, int, int, int],
                     architecture: dict[str, Any]) -> None:
    """An import's ``--json`` report: its ``checkpoint``, ``counts`` (tensors in the file, tensors of the
    network, norm3 duplicates, never-run tensors) adding up, and at least ``architecture``."""
    in_file, loaded, duplicates, unused = counts
    assert doc["checkpoint"] == checkpoint
    assert (doc["tensors_in_file"], doc["keys_loaded"], doc["duplicates"], len(doc["unused"])) == counts
    assert in_file == loaded + duplicates + unused  # every tensor of the file has its place or its reason
    assert doc["architecture"].items() >= architecture.items()


def assert_igev_family_import(home: Path, tmp_path: Path, fixture: dict[str, Any], published: Path, source: str,
                              name: str, counts: tuple[int, int, int, int]) -> dict[str, Any]:
    """`checkpoints import --from source` (IGEV's family: its cost volume's span given, --max-disp 192) of the
    seeded ``published`` file as ``name``: its report accounted, its config and source kept, and `predict`
    with it the reference's output within tolerance — no sign flip, the demo's 32 iterations by default,
    ``--iters 31`` another output. Returns the import's report."""
    imported = cli(home, "checkpoints", "import", "--from", source, str(published), "--max-disp", "192",
                   "--name", name, "--json")
    assert imported.exit_code == 0, imported.output
    doc = json.loads(imported.output)
    assert_accounted(doc, f"imported:{name}", counts, {})
    assert doc["architecture"] == {"n_gru_layers": 3, "corr_levels": 2, "corr_radius": 4, "max_disp": 192,
                                   "iterations": 32, "dtype": "float32", "given": ["max_disp"]}
    payload = load_checkpoint(home / "checkpoints" / "imported" / f"{name}.pt")
    assert payload["config"]["preset"] == source and payload["config"]["model"]["max_disp"] == 192
    assert payload["source"]["from"] == source and not payload["config"]["train"]["amp"]
    height, width = fixture["shape"]
    assert height % 32 and width % 32  # the demo's centred padding is exercised on both axes
    reference = fixture["disparity"]
    ours = predict_cli(home, tmp_path, fixture, doc["checkpoint"])  # no --iters: the demo's 32
    assert ours.shape == reference.shape == (height, width)
    assert excess(ours, reference) <= 0, f"off by up to {np.abs(ours - reference).max():.2e} px"
    assert excess(-ours, reference) > 0  # the output is the disparity as it is, no sign flip
    # --iters overrides the default: one iteration short is another output.
    assert excess(predict_cli(home, tmp_path, fixture, doc["checkpoint"], "--iters", "31"), reference) > 0
    return doc


def assert_predictor_path_catches_bugs(network: torch.nn.Module, config: Any, fixture: dict[str, Any]) -> None:
    """The predictor's path — the one `predict` and `evaluate` take — gives the fixture's reference output
    with ``network`` and ``config`` (a conversion's), and misses it under each of PADDING_BUGS."""
    predictor = predictor_module.Predictor(network, config)

    def predict() -> np.ndarray:
        return predictor.predict(fixture["left"], fixture["right"]).disparity

    assert excess(predict(), fixture["disparity"]) <= 0
    for bug, patch in PADDING_BUGS.items():
        with patch():
            assert excess(predict(), fixture["disparity"]) > 0, f"{bug} went unnoticed"


def patched(target: Any, name: str, value: Any) -> Patch:
    """A context manager factory that sets ``target.name`` to ``value`` while it is entered."""
    @contextmanager
    def patch() -> Iterator[None]:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(target, name, value)
            yield
    return patch


class _ZeroPadding:
    """torch.nn.functional, but ``pad`` fills with zeros whatever mode it is asked for."""

    def __getattr__(self, name: str) -> Any:
        return getattr(torch.nn.functional, name)

    def pad(self, x, padding, mode="constant"):  # type: ignore[no-untyped-def]
        return torch.nn.functional.pad(x, padding, mode="constant")


# Deliberate bugs of the predictor's path (the one `predict` and `evaluate` take): each must be caught.
PADDING_BUGS: dict[str, Patch] = {
    "padded bottom/right": patched(ModelConfig, "inference_padding", property(lambda self: (32, False))),
    "padded with zeros, not replicated": patched(predictor_module, "F", _ZeroPadding()),
}


def assert_evaluated_beside(home: Path, tmp_path: Path, method: str, checkpoint: str, other: str,
                            other_checkpoint: str, network: str) -> None:
    """`evaluate` on two 64×128 KITTI pairs scores ``method`` (an imported ``checkpoint``) beside ``other``
    (``other_checkpoint``) and SGBM in one report, and refuses ``method`` another network's checkpoint (the
    message names its ``network``) or no checkpoint of its own."""
    from tests.test_evaluate import _write_kitti

    _write_kitti(tmp_path / "kitti")  # two 64×128 pairs
    out = tmp_path / "report"
    result = cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti",
                 "--method", method, "--method", other, "--method", "sgbm",
                 "--checkpoint", f"{method}={checkpoint}", "--checkpoint", f"{other}={other_checkpoint}",
                 "--iters", "2", "--out", str(out), "--here", "--json")
    assert result.exit_code == 0, result.output[-2000:]
    report = json.loads(result.stdout)
    ours, theirs = method.replace("-", "_"), other.replace("-", "_")
    assert set(report["methods"]) == {ours, theirs, "sgbm"} and report["failed"] == []
    for scored in report["methods"].values():
        assert scored["regions"]["all"]["samples"] == 2 and np.isfinite(scored["regions"]["all"]["epe"])
    assert report["params"]["checkpoints"] == {ours: checkpoint, theirs: other_checkpoint}
    pfm = out / "predictions" / ours / "training" / "image_2" / "000000_10.pfm"
    assert pfm.is_file() and read_pfm(pfm).shape == (64, 128)
    # Each baseline scores its own network: another network's checkpoint is refused.
    wrong = cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti", "--method", method,
                "--checkpoint", f"{method}={other_checkpoint}", "--out", str(tmp_path / "r2"), "--here")
    assert wrong.exit_code != 0 and f"{method} scores a {network} network's checkpoint" in wrong.output
    alone = cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti", "--method", method,
                "--checkpoint", checkpoint, "--here")
    assert alone.exit_code != 0 and f"{method} needs its own checkpoint" in alone.output
