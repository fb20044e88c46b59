"""The proposal threshold (setting ``proposal_threshold``): the propose job keeps every proposal scoring at
least SCORE_FLOOR and each scan stores the threshold in force; the frame detail marks those under it
``hidden``; on submit a hidden proposal left untouched gets the fate ``hidden`` (no verdict: neither a
rejection nor a find), a hidden one decided gets its usual fate; the figures per proposer are grouped
by threshold."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select, update

from annotation.proposals.plane_break import DEFAULT_THRESHOLD, SCORE_FLOOR
from core.formats import rle_to_mask
from dataset.db import migrate, transaction
from dataset.services import jobs as job_service
from dataset.services.proposals import configured_proposers
from dataset.settings import Settings, SettingsError, load_settings
from dataset.tables import Proposal, ProposalScan
from tests.conftest import make_settings
from tests.fixtures.annotate import H, W
from tests.test_annotate import auth, truth
from tests.test_proposal_fates import _approve_all, _pair, _submit
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

TOP = 1.0  # the highest threshold: only proposals the proposer is certain of (score 1.0) are shown


def _corner() -> list[dict]:
    """A made-up illusion in the frame's corner, away from the picture: a submit needs one."""
    illusion, support = np.zeros((H, W), bool), np.zeros((H, W), bool)
    illusion[5:40, 5:60] = True
    support[0:50, 0:70] = True
    return _pair(1, illusion, support & ~illusion)


CORNER = _corner()


@pytest.fixture
def settings(tmp_path: Path, request: pytest.FixtureRequest) -> Settings:
    """The workspace's settings with the threshold the test names (``@pytest.mark.parametrize`` on it)."""
    s = make_settings(tmp_path / "ws", proposal_threshold=getattr(request, "param", TOP))
    migrate(s.database_url)
    return s


@pytest.fixture
def scene(prefiltered_scene: Path) -> Path:
    return prefiltered_scene


def _proposals(client, tokens, frame_id: int) -> list[dict]:  # type: ignore[no-untyped-def]
    return client.get(f"/api/v1/frames/{frame_id}", headers=auth(tokens)).json["proposals"]


def test_the_setting_defaults_to_plane_breaks_threshold(tmp_path: Path) -> None:
    assert make_settings(tmp_path / "a").proposal_threshold == DEFAULT_THRESHOLD
    with pytest.raises(SettingsError, match="proposal_threshold"):
        load_settings(tmp_path / "a", proposal_threshold=1.5)


@pytest.mark.parametrize("settings", [0.5], indirect=True)
def test_scans_store_the_threshold_and_the_page_is_told_which_are_hidden(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    # The job's proposers keep what scores under the threshold: the page hides it, the annotator may ask for it.
    assert all(getattr(p, "_min_score", SCORE_FLOOR) == SCORE_FLOOR for p in configured_proposers(runtime.settings))
    ids = _approve_all(client, tokens, runtime)
    job_service.run_queued_jobs(HANDLERS, runtime)
    with runtime.sessions() as s:
        assert set(s.scalars(select(ProposalScan.threshold))) == {0.5}
        scores = list(s.scalars(select(Proposal.score)))
    assert scores and min(scores) >= SCORE_FLOOR
    shown = [p for i in ids for p in _proposals(client, tokens, i)]
    assert len(shown) == len(scores)
    assert all(p["hidden"] == (p["score"] < 0.5) for p in shown)


def test_untouched_hidden_proposals_are_hidden_and_decided_ones_keep_their_fate(client, tokens, scene, runtime) -> None:  # type: ignore[no-untyped-def]
    ids = _approve_all(client, tokens, runtime)
    job_service.run_queued_jobs(HANDLERS, runtime)
    proposals = {i: _proposals(client, tokens, i) for i in ids}
    unseen = next(i for i in ids if all(p["hidden"] for p in proposals[i]))
    mixed = [i for i in ids if i != unseen and any(p["hidden"] for p in proposals[i])]
    assert len(mixed) >= 3, f"the scene no longer gives frames with hidden proposals at {TOP}: {proposals}"
    taken, turned_down = (next(p for p in proposals[i] if p["hidden"]) for i in mixed[:2])
    # A hidden one accepted as it was (the annotator asked to see all), another rejected; the picture of
    # a frame whose proposals were all hidden drawn by hand; the last frame submitted with nothing touched.
    _submit(client, tokens, mixed[0], _pair(1, rle_to_mask(taken["illusion"], (H, W)),
                                            rle_to_mask(taken["support"], (H, W)), taken["id"]))
    assert client.post(f"/api/v1/frames/{mixed[1]}/lease", headers=auth(tokens)).status_code == 200
    reject = client.post(f"/api/v1/frames/{mixed[1]}/proposals/{turned_down['id']}/reject", headers=auth(tokens))
    assert reject.status_code == 200
    _submit(client, tokens, mixed[1], CORNER)
    index = next(n for n, i in enumerate(ids) if i == unseen)
    _submit(client, tokens, unseen, _pair(1, truth(scene, index, "illusion_00"), truth(scene, index, "support_00")))
    _submit(client, tokens, mixed[2], CORNER)

    after = {p["id"]: p["fate"] for i in ids for p in _proposals(client, tokens, i)}
    assert after.pop(taken["id"]) == "accepted" and after.pop(turned_down["id"]) == "rejected"
    untouched = {p["id"]: p for ps in proposals.values() for p in ps if p["id"] in after}
    assert after == {pid: "hidden" if p["hidden"] else "rejected" for pid, p in untouched.items()}
    hidden = sum(p["hidden"] for p in untouched.values())

    stats = client.get("/api/v1/stats/proposers", headers=auth(tokens)).json["proposers"]["plane-break"]
    rejected = 1 + len(untouched) - hidden
    assert (stats["accepted"], stats["rejected"], stats["hidden"], stats["pending"]) == (1, rejected, hidden, 0)
    assert stats["acceptance_rate"] == pytest.approx(1 / (1 + rejected), abs=1e-4)  # hidden ones are no verdict
    with runtime.sessions() as s:
        misses = dict(s.execute(select(ProposalScan.frame_id, ProposalScan.misses)).all())
    assert misses[unseen] == 1, "the hand-drawn picture: its frame's proposals were never seen, so they found nothing"
    assert stats["misses"] == sum(misses.values())
    [group] = stats["by_threshold"]
    assert group == {"threshold": TOP, **{k: v for k, v in stats.items() if k != "by_threshold"}}


def test_figures_are_grouped_by_the_threshold_in_force(client, tokens, scene, runtime: Runtime) -> None:  # type: ignore[no-untyped-def]
    ids = _approve_all(client, tokens, runtime)
    job_service.run_queued_jobs(HANDLERS, runtime)
    # As if frame 0 had been scanned before the setting changed.
    with transaction(runtime.sessions) as s:
        s.execute(update(ProposalScan).where(ProposalScan.frame_id == ids[0]).values(threshold=0.3))
        low = len(s.scalars(select(Proposal).where(Proposal.frame_id == ids[0])).all())
    for i in ids:
        _submit(client, tokens, i, CORNER)
    stats = client.get("/api/v1/stats/proposers", headers=auth(tokens)).json["proposers"]["plane-break"]
    groups = {g["threshold"]: g for g in stats["by_threshold"]}
    assert list(groups) == [TOP, 0.3], "highest first"
    assert (groups[0.3]["frames"], groups[0.3]["proposals"], groups[0.3]["rejected"], groups[0.3]["hidden"]) == (1, low, low, 0)
    top = groups[TOP]
    assert (top["frames"], top["proposals"]) == (len(ids) - 1, stats["proposals"] - low) and top["hidden"] > 0
    assert top["rejected"] + top["hidden"] == top["proposals"]
    assert stats["frames"] == len(ids) and stats["rejected"] == low + top["rejected"] and stats["hidden"] == top["hidden"]
