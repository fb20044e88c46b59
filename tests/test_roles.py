"""Walk every route with every role and check the allowed/denied matrix.

The expected least role of each endpoint is written out here, independently of the views, so a
route added without an entry, or a role changed by accident, fails this test.
"""

from __future__ import annotations

import pytest

from dataset.tables import Role
from tests.conftest import login

PUBLIC = None
EXPECTED: dict[str, Role | None] = {
    "auth.healthz": PUBLIC,
    "auth.favicon": PUBLIC,
    "auth.login": PUBLIC,
    "auth.session_ended": PUBLIC,
    "exports.index": Role.curator,
    "exports.create": Role.curator,
    "exports.download": Role.curator,
    "exports.delete": Role.curator,
    "auth.logout": Role.annotator,
    "dashboard.dashboard": Role.annotator,
    "dashboard.frames": Role.annotator,
    "jobs.jobs": Role.annotator,
    "jobs.job": Role.annotator,
    "annotate.annotate": Role.annotator,
    "review.review": Role.curator,
    "ingest.ingest": Role.curator,
    "admin.users": Role.admin,
    "samples.index": Role.annotator,
    "samples.detail": Role.annotator,
    "samples.preview": Role.annotator,
    "samples.render": Role.annotator,
    "samples.scene": Role.annotator,
    "samples.viser_client": Role.annotator,
    "samples.frame_preview": Role.annotator,
    "admin.create_user": Role.admin,
    "admin.set_active": Role.admin,
    "admin.set_role": Role.admin,
    "admin.reset_password": Role.admin,
    "admin.revoke_tokens": Role.admin,
    "media.serve": Role.annotator,
    "api.openapi": Role.annotator,
    "api.me": Role.annotator,
    "api.list_users": Role.admin,
    "api.create_user": Role.admin,
    "api.frames": Role.annotator,
    "api.funnel": Role.annotator,
    "api.proposers": Role.annotator,
    "api.list_jobs": Role.annotator,
    "api.get_job": Role.annotator,
    "api.retry_job": Role.curator,
    "api.retry_failed_generates": Role.curator,
    "api.review_frames": Role.curator,
    "api.review_frame": Role.curator,
    "api.review_bulk": Role.curator,
    "api.list_videos": Role.annotator,
    "api.upload_video": Role.curator,
    "api.start_prefilter": Role.curator,
    "api.annotate_next": Role.annotator,
    "api.frame_detail": Role.annotator,
    "api.renew_lease": Role.annotator,
    "api.release_lease": Role.annotator,
    "api.segment": Role.annotator,
    "api.save_annotation": Role.annotator,
    "api.delete_frame": Role.annotator,
    "api.propagate": Role.annotator,
    "api.reject_proposal": Role.annotator,
    "api.list_samples": Role.annotator,
    "api.get_sample": Role.annotator,
    "api.review_sample": Role.curator,
    "api.regenerate_sample": Role.curator,
    "models.runs": Role.curator,
    "models.run": Role.curator,
    "models.compare": Role.curator,
    "models.val_image": Role.curator,
    "models.run_log": Role.curator,
    "models.run_log_file": Role.curator,
    "api.list_runs": Role.curator,
    "api.launch_run": Role.admin,
    "api.estimate_run": Role.admin,
    "api.get_run": Role.curator,
    "api.run_metrics": Role.curator,
    "api.cancel_run": Role.admin,
    "api.resume_run": Role.admin,
    "api.promote_run": Role.admin,
    "api.download_checkpoint": Role.curator,
    "api.list_evaluations": Role.curator,
    "api.get_evaluation": Role.curator,
    "api.launch_evaluation": Role.curator,
    "api.evaluation_file": Role.curator,
    "evaluations.index": Role.curator,
    "evaluations.report": Role.curator,
    "evaluations.sample": Role.curator,
    "evaluations.sample_image": Role.curator,
}
SAMPLE_ARGS = {"user_id": "1", "job_id": "1", "frame_id": "1", "sample_id": "1", "proposal_id": "1",
               "view": "anaglyph", "asset": "index.html",
               "key": "ab/cd/" + "ab" * 32 + ".png", "run_id": "1", "name": "best.pt",
               "evaluation_id": "1", "method": "fusion", "image": "error", "export_id": "1"}
CALLERS = ["anonymous", *(r.value for r in Role)]


def _routes(app):  # type: ignore[no-untyped-def]
    for rule in app.url_map.iter_rules():
        if rule.endpoint == "static":
            continue
        path = rule.rule
        for name in rule.arguments:
            path = path.replace(f"<int:{name}>", SAMPLE_ARGS[name]).replace(f"<path:{name}>", SAMPLE_ARGS[name])
            path = path.replace(f"<{name}>", SAMPLE_ARGS[name])
        for method in sorted(rule.methods - {"HEAD", "OPTIONS"}):
            yield rule.endpoint, method, path


def test_every_route_is_in_the_matrix(app) -> None:  # type: ignore[no-untyped-def]
    assert {endpoint for endpoint, _, _ in _routes(app)} == set(EXPECTED)


@pytest.mark.parametrize("caller", CALLERS)
def test_role_matrix(app, client, tokens, caller: str) -> None:  # type: ignore[no-untyped-def]
    headers = {} if caller == "anonymous" else {"Authorization": f"Bearer {tokens[caller]}"}
    failures = []
    for endpoint, method, path in _routes(app):
        required = EXPECTED[endpoint]
        allowed = required is PUBLIC or (caller != "anonymous" and Role(caller).allows(required))
        response = client.open(path, method=method, headers=headers, json={} if method == "POST" else None)
        denied = response.status_code in (401, 403) or (
            response.status_code == 302 and "/login?next=" in response.location)
        if allowed == denied:
            failures.append(f"{caller} {method} {path} -> {response.status_code} (expected {'allowed' if allowed else 'denied'})")
        if denied and caller == "anonymous" and path.startswith("/api/"):
            assert response.status_code == 401 and response.is_json, path
        if denied and caller != "anonymous":
            assert response.status_code == 403, path
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("caller", [r.value for r in Role])
def test_session_login_sees_the_same_matrix_for_pages(app, caller: str) -> None:  # type: ignore[no-untyped-def]
    client = app.test_client()
    assert login(client, caller).status_code == 302
    for endpoint, method, path in _routes(app):
        if method != "GET" or EXPECTED[endpoint] is PUBLIC:
            continue
        status = client.get(path).status_code
        if Role(caller).allows(EXPECTED[endpoint]):
            assert status not in (401, 403), (caller, path, status)
        else:
            assert status == 403, (caller, path, status)
