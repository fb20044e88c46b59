"""Evaluations in the database and the web: the job's rows, the API's roles and validation, report
files kept inside their folder, the Samples list by error, and one evaluated sample's pictures."""

from __future__ import annotations

from pathlib import Path

import pytest
from sqlalchemy import select

from dataset.db import transaction
from dataset.services import evaluations
from dataset.services.errors import NotFound
from dataset.tables import Evaluation, EvaluationResult
from tests.evaluations_data import STEP_PX, evaluated_database


def _auth(tokens: dict[str, str], role: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[role]}"}


@pytest.fixture
def evaluated(runtime, tmp_path: Path):  # type: ignore[no-untyped-def]
    return evaluated_database(runtime, tmp_path)


def test_the_job_records_its_evaluation_and_one_row_per_sample_and_method(runtime, evaluated) -> None:  # type: ignore[no-untyped-def]
    job_id, ids = evaluated
    with transaction(runtime.sessions) as s:
        evaluation = s.scalar(select(Evaluation).where(Evaluation.job_id == job_id))
        assert evaluation.summary["samples"] == len(ids) and evaluation.summary["database_rows"] == 2 * len(ids)
        assert evaluation.summary["headline"]["predictions"]["all"]["epe"] == pytest.approx(
            STEP_PX * (len(ids) - 1) / 2, abs=1e-3)
        rows = s.scalars(select(EvaluationResult).where(EvaluationResult.method == "predictions")
                         .order_by(EvaluationResult.sample_id)).all()
        assert [r.sample_id for r in rows] == ids
        assert [round(r.epe_all, 3) for r in rows] == [k * STEP_PX for k in range(len(ids))]
        assert all(r.epe_illusion is not None and r.prediction.endswith(".pfm") for r in rows)
        items, total = evaluations.samples_by_error(s, evaluation.id, method="predictions", min_error=1.0)
        assert total == len(ids) - 2 and [i["id"] for i in items] == ids[:1:-1]  # worst first, ≥ 1 px only


def test_api_lists_shows_and_launches_for_curators_only(client, tokens, evaluated, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    listed = client.get("/api/v1/evaluations", headers=_auth(tokens, "curator")).json["items"]
    assert len(listed) == 1 and listed[0]["state"] == "succeeded" and listed[0]["has_results"]
    assert client.get("/api/v1/evaluations", headers=_auth(tokens, "annotator")).status_code == 403
    shown = client.get(f"/api/v1/evaluations/{listed[0]['id']}", headers=_auth(tokens, "curator")).json
    assert shown["methods"] == ["predictions", "sgbm"] and shown["format"] == "database"
    bad = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "data": {"root": "x", "format": "nope"}},
                      headers=_auth(tokens, "curator"))
    assert bad.status_code == 400 and bad.json["error"].startswith("data.format: must be one of")
    nothing = client.post("/api/v1/evaluations", json={"run": 1}, headers=_auth(tokens, "curator"))
    assert nothing.status_code == 400 and nothing.json["error"] == "methods: tick at least one method to score"
    no_model = client.post("/api/v1/evaluations", json={"methods": ["fusion"], "run": 1},
                           headers=_auth(tokens, "curator"))
    assert no_model.status_code == 400 and no_model.json["error"].startswith("checkpoint: ")
    launched = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "run": 1}, headers=_auth(tokens, "curator"))
    assert launched.status_code == 202 and launched.json["state"] == "queued" and launched.json["job"]
    assert client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "run": 1},
                       headers=_auth(tokens, "annotator")).status_code == 403


def test_report_files_stay_inside_the_report_folder(client, runtime, tokens, evaluated) -> None:  # type: ignore[no-untyped-def]
    headers = _auth(tokens, "curator")
    assert client.get("/api/v1/evaluations/1/files/report.json", headers=headers).json["samples"] == len(evaluated[1])
    assert client.get("/api/v1/evaluations/1/files/report.js", headers=headers).status_code == 200
    for escape in ("../run.json", "..%2F..%2Fillusion-studio.db", "%2Fetc%2Fpasswd", "pictures/../../x"):
        assert client.get(f"/api/v1/evaluations/1/files/{escape}", headers=headers,
                          follow_redirects=True).status_code == 404, escape
    with transaction(runtime.sessions) as s:
        for escape in ("/etc/passwd", "../1/../../illusion-studio.db"):
            with pytest.raises(NotFound):
                evaluations.report_file(evaluations.get_evaluation(s, 1), escape, runtime.settings.home)


def test_samples_by_error_and_one_evaluated_sample(client, tokens, evaluated) -> None:  # type: ignore[no-untyped-def]
    _, ids = evaluated
    headers = _auth(tokens, "annotator")
    page = client.get("/api/v1/samples?evaluation=1&sort=error&method=predictions&limit=4", headers=headers).json
    assert [i["id"] for i in page["items"]] == ids[::-1][:4] and page["total"] == len(ids) and page["more"]
    assert (page["prev"], page["next"]) == (None, "4")  # offsets, as the grid's cursors
    rest = client.get("/api/v1/samples?evaluation=1&method=predictions&limit=4&offset=4&after=4", headers=headers).json
    assert [i["id"] for i in rest["items"]] == ids[::-1][4:] and (rest["prev"], rest["next"]) == ("0", None)
    assert page["items"][0]["evaluation"]["value"] == pytest.approx(STEP_PX * (len(ids) - 1), abs=1e-3)
    by_illusion = client.get("/api/v1/samples?evaluation=1&sort=bad2&region=illusion", headers=headers)
    assert by_illusion.status_code == 200 and by_illusion.json["items"][0]["evaluation"]["method"] == "predictions"
    assert client.get("/api/v1/samples?evaluation=1&region=mirror", headers=headers).status_code == 400
    curator = _auth(tokens, "curator")
    worst = ids[-1]
    html = client.get(f"/evaluations/1/samples/{worst}?method=predictions", headers=curator).get_data(as_text=True)
    assert "predictions prediction" in html and "confidence" not in html.split("evaluation-pictures")[1]
    for image in ("gt", "prediction", "error"):
        response = client.get(f"/evaluations/1/samples/{worst}/predictions/{image}.png", headers=curator)
        assert response.status_code == 200 and response.data[:4] == b"\x89PNG", image
    assert client.get(f"/evaluations/1/samples/{worst}/predictions/confidence.png", headers=curator).status_code == 404
    assert f"/evaluations/1/samples/{worst}" in client.get(f"/samples/{worst}", headers=curator).get_data(as_text=True)
    report = client.get("/evaluations/1", headers=curator).get_data(as_text=True)
    assert 'id="paper-table"' in report and "<script" not in report.split("</main>")[0]  # no inline script


def test_a_running_evaluation_says_how_far_it_is(client, runtime, tokens, evaluated) -> None:  # type: ignore[no-untyped-def]
    from dataset.tables import Job, JobState

    curator = _auth(tokens, "curator")
    launched = client.post("/api/v1/evaluations", json={"methods": ["sgbm"], "run": 1}, headers=curator)
    evaluation_id = launched.json["id"]
    html = client.get(f"/evaluations/{evaluation_id}", headers=curator).get_data(as_text=True)
    assert "No report yet (the job is queued)." in html
    with transaction(runtime.sessions) as s:
        job = s.get(Job, launched.json["job"])
        job.state, job.progress = JobState.running, 0.25
    html = client.get(f"/evaluations/{evaluation_id}", headers=curator).get_data(as_text=True)
    assert "No report yet (the job is running, 25% done" in html and ", )" not in html


def test_a_samples_provenance_reads_as_text(client, runtime, tokens, evaluated) -> None:  # type: ignore[no-untyped-def]
    from dataset.tables import Sample

    sample_id = evaluated[1][0]
    with transaction(runtime.sessions) as s:
        sample = s.get(Sample, sample_id)
        sample.provenance = {**(sample.provenance or {}),
                             "pair_types": {"illusion_01": "mirror", "illusion_00": "picture"}}
    html = client.get(f"/samples/{sample_id}", headers=_auth(tokens, "curator")).get_data(as_text=True)
    assert "<dt>pair_types</dt><dd>illusion_00: picture, illusion_01: mirror</dd>" in html
    assert "{&#39;" not in html and "{'" not in html
