"""One way to name a checkpoint: `RUN:NAME`, `imported:NAME`, or —
on the command line — a path; `runs list --json` names checkpoints the way `predict --checkpoint`
takes them; a stereo-only checkpoint predicts without a mono disparity."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from core.formats import write_rgb  # noqa: E402
from dataset.db import transaction  # noqa: E402
from dataset.services import training  # noqa: E402
from dataset.services.errors import InvalidInput, NotFound  # noqa: E402
from dataset.tables import TrainingRun  # noqa: E402
from model.checkpoint import save_checkpoint  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from model.runs import registry  # noqa: E402
from tests.model_pairs import random_dot_pair  # noqa: E402
from webapp.cli import main  # noqa: E402

# A stereo-only lite network (no mono branch input, no VLM): predicts from the pair alone.
STEREO_ONLY = {"hidden_dims": [16, 16, 16], "motion_dim": 16, "feature_dim": 32, "use_mono": False, "use_vlm": False,
               "test_iters": 1}


def _cli(home: Path, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["--data-dir", str(home), *args])


@pytest.fixture()
def pair(tmp_path: Path) -> tuple[str, str]:
    left, right, _ = random_dot_pair(32, 48, 2)
    write_rgb(tmp_path / "l.png", left)
    write_rgb(tmp_path / "r.png", right)
    return str(tmp_path / "l.png"), str(tmp_path / "r.png")


def _run_with_checkpoints(settings, runtime) -> int:  # type: ignore[no-untyped-def]
    """A finished run whose folder holds step 2's checkpoint and best.pt, as the engine leaves them."""
    with transaction(runtime.sessions) as s:
        run = TrainingRun(preset="lite", config={"train": {"steps": 2}}, dataset_id="ab" * 32, step=2, steps=2,
                          best_step=2, last_checkpoint="checkpoints/step_0000002.pt")
        s.add(run)
        s.flush()
        run_id = run.id
    config = load_preset("lite", STEREO_ONLY)
    torch.manual_seed(0)
    folder = training.run_dir(settings.runs_dir, run_id) / "checkpoints"
    for name in ("step_0000002.pt", "best.pt"):
        save_checkpoint(folder / name, FusionNetwork(config.model), config, step=2)
    return run_id


def test_runs_list_names_checkpoints_that_predict_takes(settings, runtime, pair, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    run_id = _run_with_checkpoints(settings, runtime)
    listed = json.loads(_cli(settings.home, "runs", "list", "--json").stdout)
    row = next(r for r in listed if r["run"] == run_id)
    assert row["checkpoint"] == "step_0000002.pt"  # the file, as answers always named it
    assert (row["checkpoint_name"], row["best_checkpoint_name"]) == (f"{run_id}:step_0000002.pt", f"{run_id}:best")
    for name in (row["checkpoint_name"], row["best_checkpoint_name"], f"{run_id}:last"):
        out = tmp_path / f"{name.replace(':', '_')}.pfm"
        result = _cli(settings.home, "predict", *pair, "--checkpoint", name, "--out", str(out))
        assert result.exit_code == 0 and out.is_file(), result.output
    wrong = _cli(settings.home, "predict", *pair, "--checkpoint", f"{run_id}:step_9.pt", "--out", str(tmp_path / "x.pfm"))
    assert wrong.exit_code == 1 and f"run {run_id} has no checkpoint 'step_9.pt'; it has best, last" in wrong.output
    missing = _cli(settings.home, "predict", *pair, "--checkpoint", "99:best", "--out", str(tmp_path / "x.pfm"))
    assert missing.exit_code == 1 and "no run 99 in this workspace" in missing.output


def test_imported_names_and_paths_resolve_in_one_place(tmp_path: Path, pair) -> None:  # type: ignore[no-untyped-def]
    home = tmp_path / "ws"
    home.mkdir()
    config = load_preset("lite", STEREO_ONLY)
    path = registry.imported_path(home, "mine")
    save_checkpoint(path, FusionNetwork(config.model), config, step=0)
    settings = type("S", (), {"home": home, "runs_dir": home / "runs"})()
    assert registry.resolve(settings, "imported:mine") == registry.ResolvedCheckpoint(path, "imported:mine")
    with pytest.raises(NotFound, match=r"no imported checkpoint 'other' \(imported: imported:mine;"):
        registry.resolve(settings, "imported:other")
    with pytest.raises(InvalidInput, match="imported checkpoint name '../mine'"):
        registry.resolve(settings, "imported:../mine")
    with pytest.raises(InvalidInput, match="expected RUN:NAME"):
        registry.resolve(settings, str(path))  # a request never names a path
    assert registry.resolve(None, str(path), allow_path=True).path == path  # the command line may
    with pytest.raises(InvalidInput, match="needs a workspace"):
        registry.resolve(None, "imported:mine", allow_path=True)
    by_name = _cli(home, "predict", *pair, "--checkpoint", "imported:mine", "--out", str(tmp_path / "a.pfm"))
    by_path = CliRunner().invoke(main, ["predict", *pair, "--checkpoint", str(path), "--out", str(tmp_path / "b.pfm")])
    assert by_name.exit_code == 0 and by_path.exit_code == 0, by_name.output + by_path.output
    assert (tmp_path / "a.pfm").read_bytes() == (tmp_path / "b.pfm").read_bytes()
