"""RAFT-Stereo as a baseline method: `evaluate` takes a checkpoint per network
method, so a fusion checkpoint and an imported RAFT-Stereo are scored in one report beside SGBM and
mono-gt-align; launch and evaluation requests name checkpoints as `predict --checkpoint` does."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

torch = pytest.importorskip("torch")

from core.formats import read_kitti_disparity, write_pfm  # noqa: E402
from dataset.services.errors import FieldError  # noqa: E402
from model.checkpoint import save_checkpoint  # noqa: E402
from model.fusion import GlobalFusion  # noqa: E402
from model.network import FusionNetwork  # noqa: E402
from model.presets import load_preset  # noqa: E402
from model.runs.schema import EvaluationLaunch, RunLaunch, openapi_schemas, validate  # noqa: E402
from tests.raft_golden import fixture_state, load_fixture  # noqa: E402
from tests.test_evaluate import _write_kitti  # noqa: E402
from webapp.cli import main  # noqa: E402

SMALL = {"hidden_dims": [16, 16, 16], "motion_dim": 16, "feature_dim": 32, "use_vlm": False, "test_iters": 1}


def _cli(home: Path, *args: str):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, ["--data-dir", str(home), *args])


def import_default(home: Path, tmp_path: Path, name: str = "raftstereo-sceneflow") -> str:
    """A RAFT-Stereo checkpoint in the published layout (seeded full-width weights), imported."""
    published = tmp_path / f"{name}.pth"
    torch.save(fixture_state(load_fixture("default")), published)
    result = _cli(home, "checkpoints", "import", "--from", "raft-stereo", str(published), "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.output)["checkpoint"]


def test_fusion_and_imported_raft_stereo_in_one_report(tmp_path: Path) -> None:
    home = tmp_path / "ws"
    assert _cli(home, "init").exit_code == 0
    raft = import_default(home, tmp_path)
    _write_kitti(tmp_path / "kitti")  # two 64×128 pairs
    mono = tmp_path / "mono"  # the ground truth as monocular input: what mono-gt-align and fusion read
    for png in sorted((tmp_path / "kitti" / "training" / "disp_occ_0").glob("*.png")):
        target = mono / "training" / "image_2" / png.with_suffix(".pfm").name
        target.parent.mkdir(parents=True, exist_ok=True)
        write_pfm(target, np.nan_to_num(read_kitti_disparity(png)))
    config = load_preset("lite", SMALL)
    torch.manual_seed(0)
    fusion = tmp_path / "fusion.pt"
    save_checkpoint(fusion, FusionNetwork(config.model), config, step=1)
    out = tmp_path / "report"
    result = _cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti", "--mono", str(mono),
                  "--method", "fusion", "--method", "raft-stereo", "--method", "sgbm", "--method", "mono-gt-align",
                  "--checkpoint", str(fusion), "--checkpoint", f"raft-stereo={raft}", "--iters", "2",
                  "--out", str(out), "--here", "--json")
    assert result.exit_code == 0, result.output[-2000:]
    report = json.loads(result.stdout)
    assert set(report["methods"]) == {"fusion", "raft_stereo", "sgbm", "mono_gt_align"}
    for method in report["methods"].values():
        assert method["regions"]["all"]["samples"] == 2 and np.isfinite(method["regions"]["all"]["epe"])
    assert report["failed"] == []
    assert report["params"]["checkpoints"] == {"raft_stereo": raft}
    assert (out / "predictions" / "raft_stereo" / "training" / "image_2" / "000000_10.pfm").is_file()

    # A fusion checkpoint is no RAFT-Stereo: the method says so rather than scoring the fused output.
    wrong = _cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti", "--method", "raft-stereo",
                 "--checkpoint", f"raft-stereo={fusion}", "--out", str(tmp_path / "r2"), "--here")
    assert wrong.exit_code != 0 and "RAFT-Stereo network's checkpoint" in wrong.output
    alone = _cli(home, "evaluate", "--data", str(tmp_path / "kitti"), "--format", "kitti", "--method", "raft-stereo",
                 "--checkpoint", raft, "--here")  # the default checkpoint is the fusion methods'
    assert alone.exit_code != 0 and "checkpoints: raft-stereo needs its own checkpoint" in alone.output


def test_requests_name_checkpoints_as_predict_does() -> None:
    assert validate(RunLaunch, {"init": "3:best"}).init == "3:best"
    assert validate(RunLaunch, {"init": "imported:raftstereo-sceneflow", "preset": "raft-stereo"}).preset == "raft-stereo"
    assert validate(RunLaunch, {"init": {"run": 3, "checkpoint": "last"}}).init.name == "3:last"  # the forms' object
    for body, field, words in (
            ({"init": "/etc/passwd"}, "init", "expected RUN:NAME"),
            ({"init": {"run": 3, "checkpoint": "../x"}}, "init.checkpoint", "checkpoint file name"),
            ({"init_stereo": "3:best"}, "init_stereo", "expected imported:NAME"),
            ({"init_stereo": "imported:x", "preset": "raft-stereo"}, "init_stereo", "start it with init"),
            ({"init_stereo": "imported:x", "init": "3:best"}, "init_stereo", "choose one")):
        with pytest.raises(FieldError) as caught:
            validate(RunLaunch, body)
        assert caught.value.field == field and words in str(caught.value), caught.value
    request = validate(EvaluationLaunch, {"methods": ["fusion", "raft-stereo"], "checkpoint": "2:best",
                                          "checkpoints": {"raft-stereo": "imported:rs"}})
    assert request.checkpoints == {"raft_stereo": "imported:rs"}
    for body, words in (({"methods": ["sgbm"], "checkpoints": {"sgbm": "1:best"}}, "not a network method"),
                        ({"methods": ["raft_stereo"], "checkpoints": {"raft_stereo": "/x.pt"}}, "expected RUN:NAME")):
        with pytest.raises(FieldError) as caught:
            validate(EvaluationLaunch, body)
        assert caught.value.field.startswith("checkpoints") and words in str(caught.value), caught.value
    schemas = openapi_schemas()
    assert "raft-stereo" in schemas["RunLaunch"]["properties"]["preset"]["enum"]
    assert "init_stereo" in schemas["RunLaunch"]["properties"]


def test_fusion_upsampling_honours_upsample_border() -> None:
    """The fused output's convex upsampling pads as the config says (it padded with the edge value always)."""
    torch.manual_seed(0)
    outputs = {}
    for border in ("edge", "zeros"):
        config = load_preset("lite", {**SMALL, "upsample_border": border}).model
        torch.manual_seed(0)
        fusion = GlobalFusion(config, 16).eval()
        torch.manual_seed(1)
        mono, stereo = torch.rand(1, 1, 6, 8), 5 + torch.rand(1, 1, 6, 8)
        confidence, hidden = torch.rand(1, 1, 6, 8), torch.rand(1, 16, 6, 8)
        mask = torch.rand(1, 9 * fusion.factor**2, 6, 8)
        with torch.no_grad():
            outputs[border] = fusion(mono, stereo, confidence, hidden, mask).disparity[0, 0]
    factor = outputs["edge"].shape[0] // 6
    inner = (slice(factor, -factor), slice(factor, -factor))
    assert torch.allclose(outputs["edge"][inner], outputs["zeros"][inner], atol=1e-5)
    assert (outputs["edge"] - outputs["zeros"]).abs().max() > 0.1  # the outer pixels see zeros past the border


def test_the_web_launches_raft_stereo_by_name_on_the_curated_test_split(client, tokens, runtime, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from dataset.services import jobs as job_service
    from model.raft_import import convert, strip_module
    from model.runs import registry
    from tests.evaluations_data import evaluated_database
    from webapp.jobs.handlers import HANDLERS

    _, ids = evaluated_database(runtime, tmp_path, videos=1)  # run 1, its test split: the curated samples
    headers = {"Authorization": f"Bearer {tokens['curator']}"}
    body = {"methods": ["raft-stereo", "sgbm"], "run": 1, "iters": 1, "checkpoints": {"raft-stereo": "imported:rs"}}
    missing = client.post("/api/v1/evaluations", json=body, headers=headers)
    assert missing.status_code == 400 and missing.json["field"] == "checkpoints", missing.json
    assert "no imported checkpoint 'rs'" in missing.json["error"]
    conversion = convert(strip_module(fixture_state(load_fixture("default"))))
    save_checkpoint(registry.imported_path(runtime.settings.home, "rs"), conversion.network, conversion.config, step=0)
    launched = client.post("/api/v1/evaluations", json=body, headers=headers)
    assert launched.status_code == 202, launched.json
    assert str(runtime.settings.home) not in json.dumps(launched.json)
    job = launched.json["job"]
    assert job_service.execute_job(job, {"evaluate": HANDLERS["evaluate"]}, runtime).value == "succeeded"
    shown = client.get(f"/api/v1/evaluations/{launched.json['id']}", headers=headers).json
    assert shown["methods"] == ["raft_stereo", "sgbm"] and shown["state"] == "succeeded", shown
    report = json.loads(client.get(f"/api/v1/evaluations/{launched.json['id']}/files/report.json", headers=headers).data)
    assert report["methods"]["raft_stereo"]["regions"]["all"]["samples"] == len(ids)
    assert report["params"]["checkpoints"] == {"raft_stereo": "imported:rs"}


def test_bench_model_offers_to_skip_raft_stereo() -> None:
    result = CliRunner().invoke(main, ["bench", "model", "--help"])
    assert result.exit_code == 0 and "--no-raft-stereo" in result.output
    assert "RAFT-Stereo's" in result.output and "network" in result.output
