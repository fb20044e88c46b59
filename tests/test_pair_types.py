"""One illusion type per illusion/support pair (a frame can hold a picture and a mirror): the
annotation keeps it, generation records it, the dataset version, its reader and COCO use it."""

from __future__ import annotations

from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import select, text

from benchmarks.scale import seed
from dataset.db import alembic_config, make_engine, transaction
from dataset.export.coco import coco_document
from dataset.export.native import export_native
from dataset.export.selection import select_samples
from dataset.readers import open_reader
from dataset.readers.version import VersionReader, pin_dataset_version
from dataset.samples import load_output
from dataset.services.annotate import save_annotation
from dataset.services.demo import true_regions
from dataset.services.errors import InvalidInput
from dataset.tables import Frame, Region, Sample, SampleState, User
from tests.test_generate import _user, generate_all, prepare
from webapp.runtime import Runtime


def _annotate(runtime: Runtime, types: dict[int, str]) -> None:
    with transaction(runtime.sessions) as s:
        user = s.scalar(select(User)) or _user(s)
        for frame in s.scalars(select(Frame).order_by(Frame.index)):
            regions = [{**r, "illusion_type": types.get(r["pair"])} for r in true_regions(runtime.media, frame, frame.video)]
            save_annotation(s, frame.id, user, version=0, regions=regions, illusion_type="picture", submit=True)


def test_a_pair_keeps_its_own_type_from_annotation_to_coco(runtime: Runtime, tmp_path: Path) -> None:
    prepare(runtime, tmp_path, n_frames=1, annotate=False)  # the synthetic frame: a picture (pair 0), a mirror (1)
    _annotate(runtime, {1: "mirror"})  # pair 0 takes the annotation's type
    with runtime.sessions() as s:
        assert {(r.pair, r.kind.value, r.illusion_type.value) for r in s.scalars(select(Region))} == {
            (0, "illusion", "picture"), (0, "support", "picture"), (1, "illusion", "mirror"), (1, "support", "mirror")}
    generate_all(runtime)
    with transaction(runtime.sessions) as s:
        sample = s.scalar(select(Sample))
        assert sample.provenance["pair_types"] == {"illusion_00": "picture", "illusion_01": "mirror"}
        sample.state = SampleState.accepted
    with runtime.sessions() as s:
        version = pin_dataset_version(s, runtime.media)
        [record] = select_samples(s, ["accepted"])
    [item] = version["items"]
    assert item["pair_types"] == {"illusion_00": "picture", "illusion_01": "mirror"}
    assert item["illusion_types"] == ["mirror", "picture"]
    regions = VersionReader(version, runtime.settings.media_root)[0].regions
    assert regions["mirror"].any() and regions["picture"].any() and not (regions["mirror"] & regions["picture"]).any()
    doc = coco_document("train", [(record, "left.png")], lambda key: load_output(runtime.media, key, "mask"))
    names = {c["id"]: c["name"] for c in doc["categories"]}
    by_pair = {(a["attributes"]["pair"], a["attributes"]["kind"]): names[a["category_id"]] for a in doc["annotations"]}
    assert by_pair[(0, "illusion")] == "picture/illusion" and by_pair[(1, "illusion")] == "mirror/illusion"
    assert by_pair[(1, "support")] == "mirror/support"
    export_native([record], runtime.media, tmp_path / "native", spec={"train": 1.0}, seed=0, progress=lambda *_: None)
    exported = open_reader("native", tmp_path / "native")[0]
    assert exported.meta["illusion_types"] == ["mirror", "picture"] and exported.regions["mirror"].any()


def test_a_pair_with_two_types_is_refused(runtime: Runtime, tmp_path: Path) -> None:
    prepare(runtime, tmp_path, n_frames=1, annotate=False)
    with transaction(runtime.sessions) as s:
        user = s.scalar(select(User)) or _user(s)
        frame = s.scalar(select(Frame))
        regions = true_regions(runtime.media, frame, frame.video)
        regions = [{**r, "illusion_type": "mirror" if r["kind"] == "illusion" else "picture"} for r in regions]
        with pytest.raises(InvalidInput, match="pair 0 has two illusion types"):
            save_annotation(s, frame.id, user, version=0, regions=regions, illusion_type="picture", submit=True)


def test_migration_gives_each_existing_pair_its_annotations_type(db_url: str) -> None:
    cfg = alembic_config(db_url)
    command.upgrade(cfg, "0001")  # the revision the seed writes
    engine = make_engine(db_url)
    with engine.begin() as conn:
        seed(conn, 60)  # typed annotations, no regions yet
        conn.execute(text("UPDATE annotations SET illusion_type = NULL WHERE id = (SELECT min(id) FROM annotations)"))
        annotations = conn.execute(text("SELECT id, illusion_type FROM annotations ORDER BY id")).all()
        for ann_id, _ in annotations:
            for kind in ("illusion", "support"):
                conn.execute(text("INSERT INTO regions (annotation_id, pair, kind, mask_rle, clicks) "
                                  "VALUES (:a, 0, :k, '{}', '[]')"), {"a": ann_id, "k": kind})
    command.upgrade(cfg, "0004")
    with engine.connect() as conn:
        typed = dict(annotations)
        rows = conn.execute(text("SELECT annotation_id, illusion_type FROM regions")).all()
    assert len(rows) == 2 * len(annotations) and any(typed.values()) and None in typed.values()
    assert all(t == typed[a] for a, t in rows)
    command.downgrade(cfg, "0003")
    command.upgrade(cfg, "head")
    engine.dispose()
