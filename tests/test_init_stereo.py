"""Starting the fusion network's stereo branch from an imported RAFT-Stereo checkpoint:
the mapped tensors compute what RAFT-Stereo's did (motion encoder zero-padded, flow x as
−disparity, gru0's columns moved, the head's row 0 negated); the engine loads the tensors that fit,
records which started fresh, and the run's JSON says so."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from dataset.services.training import INIT_FILE, init_report  # noqa: E402
from model.checkpoint import load_fitting, save_checkpoint  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from model.raft_import import convert, stereo_branch_state, strip_module  # noqa: E402
from model.stereo.raft import StereoBranch  # noqa: E402
from model.train import EXIT_SUCCEEDED  # noqa: E402
from tests.raft_golden import fixture_state, load_fixture  # noqa: E402
from tests.train_runs import make_run, parameters, train_here  # noqa: E402

# A fusion preset whose stereo branch has RAFT-Stereo's widths (lite keeps n_downsample 3: its
# feature encoder and mask head differ, so they start fresh).
WIDE = {"hidden_dims": [128, 128, 128], "motion_dim": 128, "feature_dim": 256, "use_vlm": False}


class _Holder(torch.nn.Module):
    """The paper preset's stereo branch alone (its mono branch loads Depth Anything's weights)."""

    def __init__(self) -> None:
        super().__init__()
        self.stereo_branch = StereoBranch(load_preset("paper").model, 256)


def _raft_network() -> FusionNetwork:
    """The raft-stereo network holding the seeded published-layout weights (tests/raft_golden.py)."""
    return convert(strip_module(fixture_state(load_fixture("default")))).network


def test_mapped_tensors_compute_what_raft_stereo_did() -> None:
    raft = _raft_network()
    ours = _Holder().eval()
    fitted, unused = stereo_branch_state(raft.trainable_state_dict(), ours.state_dict())
    report = load_fitting(ours, fitted)
    assert len(report["loaded"]) == 74 and report["unused"] == []  # the count for paper
    assert all(".context.blocks." in k or ".context.heads." in k for k in report["fresh"] if "num_batches" not in k)
    assert unused and all(".cnet." in k for k in unused)  # RAFT's image context encoder has no counterpart
    theirs, mine = raft.stereo_branch.update, ours.stereo_branch.update
    torch.manual_seed(0)
    corr, disparity = torch.randn(1, 36, 6, 8), 3 * torch.randn(1, 1, 6, 8)
    flow = torch.cat([-disparity, torch.zeros_like(disparity)], 1)  # RAFT-Stereo's flow: x = −disparity, y = 0
    hidden, coarser = torch.randn(1, 128, 6, 8), torch.randn(1, 128, 6, 8)
    context = [torch.randn(1, 128, 6, 8) for _ in range(3)]
    with torch.no_grad():
        motion_theirs, motion_mine = theirs.motion(corr, flow), mine.motion(corr, disparity)
        assert torch.allclose(motion_mine[:, :126], motion_theirs[:, :126], atol=1e-5)
        assert motion_mine[:, 126].abs().max() == 0 and torch.equal(motion_mine[:, 127:], disparity)
        gru_theirs = theirs.grus[0](hidden, context, motion_theirs, coarser)
        gru_mine = mine.gru0(hidden, context, motion_mine, coarser)
        assert torch.allclose(gru_mine, gru_theirs, atol=1e-5)
        assert torch.allclose(mine.disp_head(hidden), -theirs.flow_head(hidden)[:, :1], atol=1e-5)
        assert torch.allclose(mine.mask.net(hidden), theirs.mask.net(hidden), atol=1e-5)


@pytest.mark.slow
def test_engine_starts_the_stereo_branch_from_an_imported_checkpoint(native: Path, tmp_path: Path) -> None:
    imported = tmp_path / "imported" / "rs.pt"
    raft = _raft_network()
    save_checkpoint(imported, raft, convert(strip_module(fixture_state(load_fixture("default")))).config, step=0)
    run_dir = make_run(tmp_path / "run", native, val=False, steps=1, lr=1e-20, **WIDE)
    doc = json.loads((run_dir / "run.json").read_text())
    (run_dir / "run.json").write_text(json.dumps({**doc, "init_stereo": str(imported)}))
    assert train_here(run_dir) == EXIT_SUCCEEDED
    record = json.loads((run_dir / INIT_FILE).read_text())
    assert len(record["loaded"]) == 41 and record["fresh"] and any(".cnet." in k for k in record["unused"])
    trained = parameters(run_dir, 1)
    for key in ("stereo_branch.context.zqr.0.weight", "stereo_branch.update.gru1.convz.weight"):
        assert key in record["loaded"]
        mapped = raft.trainable_state_dict()[key.replace("context.zqr", "zqr").replace("gru1", "grus.1")]
        assert (trained[key] - mapped).abs().max() < 1e-6  # the step with lr 1e-20 left it where it started
    shown = init_report(run_dir, "imported:rs")
    assert shown["source"] == "imported:rs" and shown["loaded"] == 41 and shown["fresh"] == len(record["fresh"])
    assert shown["loaded_keys"] == record["loaded"] and str(tmp_path) not in json.dumps(shown)


# A RAFT-Stereo network as narrow as lite's stereo branch: a file whose every stereo tensor fits lite.
LITE_WIDTHS = {"n_downsample": 3, "encoder_dims": [16, 32, 48], "encoder_blocks": [0, 1, 1], "stem_kernel": 3,
               "feature_dim": 48, "hidden_dims": [32, 32, 32]}


def test_a_launch_names_init_stereo_and_the_run_says_what_it_started_from(client, tokens, runtime) -> None:  # type: ignore[no-untyped-def]
    from dataset.db import transaction
    from model.runs import registry
    from tests.runs_data import add_accepted_samples
    from tests.test_runs import SHORT, bearer

    with transaction(runtime.sessions) as s:
        add_accepted_samples(s, runtime.media, videos=3)
    headers = bearer(tokens, "admin")
    save_checkpoint(registry.imported_path(runtime.settings.home, "rs"), _raft_network(),
                    convert(strip_module(fixture_state(load_fixture("default")))).config, step=0)
    for body, field, words in (({"init_stereo": "imported:nope"}, "init_stereo", "no imported checkpoint 'nope'"),
                               ({"init": "imported:nope"}, "init", "no imported checkpoint 'nope'"),
                               ({"init": "99:best"}, "init", "no run 99")):
        refused = client.post("/api/v1/runs", json={"preset": "lite", **SHORT, **body}, headers=headers)
        assert refused.status_code == 400 and refused.json["field"] == field and words in refused.json["error"], refused.json
    # A file whose widths are not lite's stereo branch's is refused at launch, naming the preset it fits.
    misfit = client.post("/api/v1/runs", json={"preset": "lite", **SHORT, "init_stereo": "imported:rs"}, headers=headers)
    assert misfit.status_code == 400 and misfit.json["field"] == "init_stereo", misfit.json
    assert "n_downsample" in misfit.json["error"] and "(it fits: paper)" in misfit.json["error"]
    narrow = load_preset("raft-stereo", LITE_WIDTHS)
    save_checkpoint(registry.imported_path(runtime.settings.home, "rs-lite"), FusionNetwork(narrow.model), narrow, step=0)
    launched = client.post("/api/v1/runs", json={"preset": "lite", **SHORT, "init_stereo": "imported:rs-lite"},
                           headers=headers)
    assert launched.status_code == 202, launched.json
    run = launched.json
    assert run["launch"]["init_stereo"] == "imported:rs-lite" and run["init"] == {"source": "imported:rs-lite"}
    doc = json.loads((runtime.settings.home / run["run_dir"] / "run.json").read_text())
    assert doc["init_stereo"] == str(registry.imported_path(runtime.settings.home, "rs-lite"))
    # The engine's record, once it has started, is what the run's JSON counts and lists.
    (runtime.settings.home / run["run_dir"] / INIT_FILE).write_text(
        json.dumps({"loaded": ["a", "b"], "fresh": ["c"], "unused": []}))
    shown = client.get(f"/api/v1/runs/{run['run']}", headers=headers).json["init"]
    assert (shown["loaded"], shown["fresh"], shown["fresh_keys"]) == (2, 1, ["c"])
    # RAFT-Stereo's own network is a preset a launch offers, fine-tuned from an imported checkpoint.
    baseline = client.post("/api/v1/runs", json={"preset": "raft-stereo", **SHORT, "crop": "64x96", "init": "imported:rs"},
                           headers=headers)
    assert baseline.status_code == 202 and baseline.json["launch"]["init_checkpoint"] == "imported:rs", baseline.json


def test_train_names_its_start_as_predict_does(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from webapp.cli import main

    home = tmp_path / "ws"

    def cli(*args: str):  # type: ignore[no-untyped-def]
        return CliRunner().invoke(main, ["--data-dir", str(home), *args])

    assert cli("init").exit_code == 0
    stereo = cli("train", "--init-stereo", "imported:nope")
    assert stereo.exit_code != 0 and "init_stereo: no imported checkpoint 'nope'" in stereo.output, stereo.output
    named = cli("train", "--preset", "raft-stereo", "--init", "imported:nope")
    assert named.exit_code != 0 and "init: no imported checkpoint 'nope'" in named.output, named.output
    missing = cli("train", "--init", str(tmp_path / "none.pt"))
    assert missing.exit_code != 0 and "is no file (nor RUN:NAME or imported:NAME)" in missing.output, missing.output
