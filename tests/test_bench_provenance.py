"""The benchmark's records can rebuild what they report — the committed trunk is the one
every JSON cites, its record holds the config it really trained with and a hash of its data, and the
provenance helpers hash what they say they hash."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from pathlib import Path

import pytest

from benchmarks import provenance
from model.presets import Config

ROOT = Path(__file__).parents[1]
BENCH = ROOT / "docs" / "bench"
TRUNK = BENCH / "trunk" / "trunk.safetensors"
# What lite turned on after the committed trunk was trained: the gate, the cross-entropy confidence
# loss at weight 5, the deterministic flow, the EfficientNet eye, then (protocol 3) the confidence's view
# of the mono, the fitted mono as its target's reference and the stereo's upsampling mask in the fusion.
LATER_FIELDS = {"model.fusion_gate", "train.confidence_loss", "train.ce_weight", "model.flow_noise", "model.vlm_eye",
                "model.confidence_sees_mono", "model.fusion_mask_from_stereo", "train.confidence_target", "train.freeze_trunk"}
# Fields added to the config after the trunk's record was written: their defaults are what the code of that
# day did (the paper's design), so the record still rebuilds its network.
ADDED_FIELDS = {"model.confidence_sees_mono", "model.fusion_mask_from_stereo", "train.freeze_trunk"}


def _record() -> dict:
    return json.loads((BENCH / "trunk" / "trunk.json").read_text())


def test_every_record_cites_a_committed_trunk() -> None:
    """Each committed trunk file is the one its record names, and every benchmark JSON that starts from a
    trunk cites one of them, of its kind: the protocol-2 figures and pre-training the no-VLM trunk, the
    stereo-only records a stereo-only one, the matcher's-truth records a matcher-trained one."""
    committed = {}
    for file in sorted((BENCH / "trunk").glob("*.safetensors")):
        digest = hashlib.sha256(file.read_bytes()).hexdigest()
        assert json.loads(file.with_suffix(".json").read_text())["sha256"] == digest, file.name
        committed[digest] = file.name
    assert _record()["sha256"] == hashlib.sha256(TRUNK.read_bytes()).hexdigest()
    cited = {}
    for path in sorted(BENCH.glob("fusion-*.json")):
        pretrained = json.loads(path.read_text()).get("pretrained")
        if pretrained is not None:
            cited[path.name] = pretrained["sha256"]
    for path in sorted(BENCH.glob("pretrain-*.json")):
        cited[path.name] = json.loads(path.read_text())["trunk"]["sha256"]
    assert len(cited) >= 9  # the six protocol-2 figures, two pre-training runs, the protocol-3 checks
    trunks = {name: committed.get(digest) for name, digest in cited.items()}
    assert None not in trunks.values(), {name: trunk for name, trunk in trunks.items() if trunk is None}
    for name, trunk in trunks.items():  # a record's name says which kind of trunk it started from
        assert ("stereo-only" in trunk) == ("stereo-only" in name) and ("matcher" in trunk) == ("matcher" in name), (name, trunk)
    assert trunks["pretrain-2026-12-03.json"] == "trunk.safetensors"


def test_the_trunk_record_holds_the_config_it_trained_with() -> None:
    recipe = _record()["recipe"]
    recorded = recipe["resolved_config"]
    rebuilt = Config.from_dict(recorded).to_dict()  # a whole, valid config
    assert {f"{s}.{k}" for s in ("model", "train") for k in rebuilt[s] if k not in recorded[s]} == ADDED_FIELDS
    assert all(rebuilt[s][k] is False for s, k in (field.split(".") for field in ADDED_FIELDS))
    assert {s: {k: v for k, v in part.items() if k in recorded[s]} if isinstance(part, dict) else part
            for s, part in rebuilt.items()} == recorded
    today = provenance.resolved_config(recipe["preset"], recipe["overrides"])
    differences = provenance.config_differences(recorded, today)
    assert set(differences) == LATER_FIELDS
    assert recorded["model"]["fusion_gate"] is False and recorded["train"]["confidence_loss"] == "focal"
    assert recorded["model"]["use_vlm"] is False and recorded["train"]["steps"] == 2000
    assert re.fullmatch(r"[0-9a-f]{64}", recipe["data_sha256"])


def test_the_sources_fingerprint_covers_training_and_sees_an_edit(tmp_path: Path) -> None:
    covers = provenance.TRAINING_SOURCES
    for needed in ("model", "dataset/readers", "dataset/services/training.py", "dataset/export/splits.py",
                   "webapp/jobs/handlers.py"):
        assert needed in covers
    real = provenance.training_sources_fingerprint()
    assert real["covers"] == list(covers) and real["files"] == len(provenance.source_files())
    assert ROOT / "model" / "runs" / "handlers.py" in provenance.source_files()  # the training job the handlers run
    # A copy of two covered entries: equal bytes, equal hash; one byte changed anywhere, another hash.
    for entry in ("model/presets.py", "dataset/export/splits.py"):
        (tmp_path / entry).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / entry, tmp_path / entry)
    small = ("model", "dataset/export/splits.py")
    before = provenance.training_sources_fingerprint(tmp_path, small)
    assert before == provenance.training_sources_fingerprint(tmp_path, small) and before["files"] == 2
    split = tmp_path / "dataset/export/splits.py"
    split.write_bytes(split.read_bytes() + b"\n")
    assert provenance.training_sources_fingerprint(tmp_path, small)["sha256"] != before["sha256"]
    (tmp_path / "model" / "new.py").write_text("")
    assert provenance.training_sources_fingerprint(tmp_path, small)["files"] == 3
    with pytest.raises(FileNotFoundError):
        provenance.training_sources_fingerprint(tmp_path, ("webapp/jobs/handlers.py",))


def test_source_commit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    found = provenance.source_commit()
    if found["commit"] is None:
        pytest.skip("not a git checkout")
    assert re.fullmatch(r"[0-9a-f]{40}", found["commit"]) and isinstance(found["dirty"], bool)
    assert provenance.source_commit(tmp_path) == {"commit": None, "dirty": None}
    monkeypatch.setenv("PATH", str(tmp_path))  # no git to run
    assert provenance.source_commit() == {"commit": None, "dirty": None}


def test_the_pretrain_data_digest_is_deterministic_and_names_its_seeds() -> None:
    first = provenance.pretrain_data_digest([10_000, 10_001], 1)
    assert re.fullmatch(r"[0-9a-f]{64}", first)
    assert provenance.pretrain_data_digest([10_000, 10_001], 1) == first
    assert provenance.pretrain_data_digest([10_000, 10_002], 1) != first


def test_the_provenance_block_a_benchmark_json_carries() -> None:
    block = provenance.provenance_block("lite", {"fusion": {}, "no_vlm": {"model.use_vlm": False}})
    assert set(block) == {"commit", "sources", "resolved_configs"}
    assert block["sources"] == provenance.training_sources_fingerprint()
    configs = block["resolved_configs"]
    assert configs["fusion"]["model"]["use_vlm"] is True and configs["no_vlm"]["model"]["use_vlm"] is False
    json.dumps(block)  # JSON-able as it stands


def test_bench_pretrain_records_what_rebuilds_its_trunk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """run_pretrain's recipe (the workspace, training and rendering faked): the resolved config of its
    overrides, the digest of the seeds it imported, the commit and the sources' fingerprint."""
    from types import SimpleNamespace

    from benchmarks import fusion, pretrain

    class Sessions:
        def __init__(self) -> None:
            self.session = SimpleNamespace(get=lambda _model, _id: SimpleNamespace(best_step=4))

        def __enter__(self) -> object:
            return self.session

        def __exit__(self, *_: object) -> None:
            pass

    rt = SimpleNamespace(sessions=Sessions, close=lambda: None)
    digests: list[tuple[tuple[int, ...], int]] = []
    saved: dict = {}
    homes: list[Path] = []
    monkeypatch.setattr(fusion, "bench_workspace", lambda home, _data: homes.append(home) or (rt, None))
    truths: list[str] = []
    monkeypatch.setattr(fusion, "import_captures",
                        lambda _rt, _seeds, _frames, truth: truths.append(truth) or {"mirror_fooling_px": {}})
    monkeypatch.setattr(fusion, "finish_workspace", lambda _home, _data, conditions: conditions)
    monkeypatch.setattr(fusion, "launch_run", lambda *_a, **_k: 7)
    monkeypatch.setattr(fusion, "run_jobs", lambda *_a, **_k: None)
    monkeypatch.setattr(fusion, "trained_checkpoint", lambda _rt, _run: (tmp_path / "best.pt", 1.0))
    monkeypatch.setattr(fusion, "held_out_samples", lambda _seeds: [])
    monkeypatch.setattr(fusion, "condition_values", lambda _samples: {})
    monkeypatch.setattr(fusion, "condition_ranges", lambda _values: {})
    monkeypatch.setattr(provenance, "pretrain_data_digest",
                        lambda seeds, frames, truth: digests.append((tuple(seeds), frames)) or "ab" * 32)
    paths: list[Path] = []
    monkeypatch.setattr(pretrain, "save_trunk",
                        lambda _ckpt, path, recipe: paths.append(path) or saved.update(recipe) or {"sha256": "x"})
    pretrain.run_pretrain(tmp_path, videos=3, frames=2, steps=5)
    assert digests == [((10_000, 10_001, 10_002), 2)]  # once, when the workspace is prepared
    assert saved["data_sha256"] == "ab" * 32
    assert saved["resolved_config"] == provenance.resolved_config("lite", pretrain.pretrain_overrides(5))
    assert saved["resolved_config"]["train"]["steps"] == 5 and saved["resolved_config"]["model"]["use_vlm"] is False
    assert saved["provenance"]["sources"] == provenance.training_sources_fingerprint()
    assert set(saved["provenance"]["commit"]) == {"commit", "dirty"}
    # the stereo-only trunk: a network that never reads the mono, kept in a file of its own
    pretrain.run_pretrain(tmp_path, videos=3, frames=2, steps=5, stereo_only=True)
    assert paths == [tmp_path / "pretrain" / "trunk.safetensors", tmp_path / "pretrain" / "trunk-stereo-only.safetensors"]
    assert saved["resolved_config"]["model"]["use_mono"] is False and saved["command"].endswith("--stereo-only")
    # on the matcher's truth: a workspace and a trunk of its own, its data hashed with that truth
    pretrain.run_pretrain(tmp_path, videos=3, frames=2, steps=5, stereo_only=True, truth="matcher")
    assert paths[-1] == tmp_path / "pretrain" / "trunk-stereo-only-matcher.safetensors"
    assert homes[-1] == tmp_path / "pretrain" / "workspace-matcher" and truths[-1] == "matcher"
    assert saved["data"]["truth"] == "matcher" and saved["command"].endswith("--stereo-only --truth matcher")
    trunk = fusion.Trunk({}, "x", {"overrides": saved["overrides"]}, "trunk-stereo-only.safetensors")
    assert fusion.trunk_network(trunk) is fusion.ABLATIONS[1]
    assert fusion.trunk_network(fusion.Trunk({}, "x", {"overrides": {}}, "t")) is fusion.TRUNK_AT_0
