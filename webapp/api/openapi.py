"""The OpenAPI 3.1 description of ``/api/v1`` (a test keeps it and the routes in step)."""

from __future__ import annotations

from typing import Any

from dataset.services.users import MAX_PASSWORD, MIN_PASSWORD
from dataset.tables import IllusionType
from model.runs.schema import openapi_schemas


def _ref(name: str) -> dict[str, str]:
    return {"$ref": f"#/components/schemas/{name}"}


def _json(schema: dict[str, Any]) -> dict[str, Any]:
    return {"application/json": {"schema": schema}}


def _list(name: str, **extra: Any) -> dict[str, Any]:
    """An object whose ``items`` are ``name`` schemas (and ``extra`` properties)."""
    return {"type": "object", "properties": {"items": {"type": "array", "items": _ref(name)}, **extra}}


# Statuses any operation may answer, whatever it does; _op adds the others where they apply.
_ANY = {
    "400": "bad input: a malformed query or body, a null byte in the URL, or (session callers) a failed CSRF check",
    "401": "no valid credentials: log in or send 'Authorization: Bearer <token>'",
    # webapp/bodies.py limits every route's body, an operation's that takes none included.
    "413": "the request body is larger than this operation takes (an upload: the max_upload_mb setting)",
    "429": "too many bad API tokens from this address or for this token's account; Retry-After says when to retry",
}
_ABOVE_ANNOTATOR = {"403": "the caller's role is below the one this operation needs"}
_WITH_ID = {"404": "no such row: an id in the path names nothing (or nothing the caller may see)"}
_QUEUE_DOWN = {"503": "the job queue is unreachable: nothing was queued or written; try again in a minute"}


def _error(description: str) -> dict[str, Any]:
    """An error response: a JSON body ``{"error", "status"}`` (the API never answers an HTML page)."""
    return {"description": description, "content": _json(_ref("Error"))}


def _op(summary: str, role: str, *, params: list[dict[str, Any]] | None = None, body: str | None = None,
        body_type: str = "application/json", ok: str = "200", schema: str | None = None,
        files: tuple[str, ...] = (), errors: dict[str, str] | None = None) -> dict[str, Any]:
    """An operation: its success ``ok`` (a JSON ``schema``, else the ``files`` media types it serves) and
    every status it can answer: those of :data:`_ANY`; 403 above the annotator role; 404 with ids in
    the path; the download statuses with ``files``; and its own ``errors`` (status → why; they may
    reword the ones above)."""
    params = params or []
    if files:
        success = {"description": "the file", "content": {t: {"schema": {"type": "string", "format": "binary"}}
                                                         for t in files}}
    else:
        success = {"description": "success", "content": _json(_ref(schema) if schema else {"type": "object"})}
    reasons = {**_ANY, **(_ABOVE_ANNOTATOR if role != "annotator" else {}),
               **(_WITH_ID if any(p["in"] == "path" for p in params) else {}), **(errors or {})}
    responses: dict[str, Any] = {ok: success}
    if files:  # send_file honours Range and the validators (If-None-Match, …)
        responses["206"] = {**success, "description": "part of the file (a Range request)"}
        responses["304"] = {"description": "not modified since the validators the request sent"}
        reasons["416"] = "the requested range lies outside the file"
    responses.update({code: _error(why) for code, why in sorted(reasons.items())})
    op: dict[str, Any] = {"summary": summary, "description": f"Needs the **{role}** role (or higher).",
                          "parameters": params, "responses": responses}
    if body:
        op["requestBody"] = {"required": True, "content": {body_type: {"schema": _ref(body)}}}
    return op


def _q(name: str, typ: str = "integer", desc: str = "") -> dict[str, Any]:
    return {"name": name, "in": "query", "required": False, "schema": {"type": typ}, "description": desc}


_ILLUSION_TYPES = [t.value for t in IllusionType]
_JOB_ID = {"name": "job_id", "in": "path", "required": True, "schema": {"type": "integer"}}
_SAMPLE_ID = {"name": "sample_id", "in": "path", "required": True, "schema": {"type": "integer"}}
# Keyset paging: a page's ``next``/``prev`` cursors, sent back as after=/before= (then offset is not applied).
_CURSORS = [_q("after", "string", "the next cursor of a page: the page after it"),
            _q("before", "string", "the prev cursor of a page: the page before it")]
_PAGED = {"total": {"type": "integer"}, "prev": {"type": ["string", "null"], "description": "null on the first page"},
          "next": {"type": ["string", "null"], "description": "null on the last page"}}
_FRAME_ID = {"name": "frame_id", "in": "path", "required": True, "schema": {"type": "integer"}}
_PROPOSAL_ID = {"name": "proposal_id", "in": "path", "required": True, "schema": {"type": "integer"}}
_EVALUATION_ID = {"name": "evaluation_id", "in": "path", "required": True, "schema": {"type": "integer"}}
# The Samples list by an evaluation's error (offset paging; state/flagged/cursors do not apply then).
_BY_ERROR = [_q("evaluation", desc="an evaluation id: its database samples, worst first"),
             _q("sort", "string", "error (EPE, default) or bad2"), _q("method", "string", "default: its first method"),
             _q("region", "string", "all (default) or illusion"),
             _q("min_error", "number", "only samples at or above it (EPE px, bad-2 %)")]
# What an evaluation's report folder holds (model/runs/report.py), as served: named types, else octet-stream.
_REPORT_FILES = ("application/json", "text/csv", "text/html", "text/plain", "text/javascript", "image/png",
                 "application/octet-stream")
# Frames sent back to the caller while it holds another: a count and the oldest few.
_RETURNED_WAITING = {"type": ["object", "null"], "description": "{count, frames: [{frame_id, sample_id, reason, note, by, "
                                                                "at, annotator}]}: frames sent back to the caller meanwhile"}
# A proposer's figures (GET /stats/proposers), over all its scans and per threshold in force.
_PROPOSER_FIGURES = {"frames": {"type": "integer"}, "proposals": {"type": "integer"}, "pending": {"type": "integer"},
                     "accepted": {"type": "integer"}, "edited": {"type": "integer"}, "rejected": {"type": "integer"},
                     "hidden": {"type": "integer", "description": "under the threshold and left untouched"},
                     "acceptance_rate": {"type": ["number", "null"]}, "median_iou": {"type": ["number", "null"]},
                     "misses": {"type": "integer"}, "ms_per_frame": {"type": ["number", "null"]}}
_RUN_ID = {"name": "run_id", "in": "path", "required": True, "schema": {"type": "integer"}}
_CHECKPOINT = {"name": "name", "in": "path", "required": True, "schema": {"type": "string"},
               "description": "a file name from the run's checkpoints (best.pt, step_0001000.pt, …)"}


_SAMPLE_BLOCKER = {"type": ["string", "null"],
                   "description": "why this workspace cannot make samples of the video's frames (no depth model "
                                  "configured and no depth of the video's own), or null when it can"}
_GENERATE_FAILED = {"type": ["object", "null"],
                    "description": "the frame's last generate job, when it failed and the frame still has no sample: "
                                   "job_id, error, finished_at (POST /jobs/{job_id}/retry once the cause is fixed)"}


def openapi_document() -> dict[str, Any]:
    """The document ``/api/v1/openapi.json`` serves: every operation with each status and content type it answers."""
    return {
        "openapi": "3.1.0",
        "info": {"title": "Illusion Studio API", "version": "1"},
        "servers": [{"url": "/api/v1"}],
        "security": [{"bearer": []}, {"session": []}],
        "paths": {
            "/openapi.json": {"get": _op("This document", "annotator")},
            "/me": {"get": _op("The calling user", "annotator", schema="User")},
            "/users": {
                "get": _op("List users", "admin", schema="UserList"),
                "post": _op("Create a user", "admin", body="NewUser", ok="201", schema="User",
                            errors={"409": "a user of that name (ignoring case) exists"}),
            },
            "/frames": {"get": _op("List frames, ordered by video and time", "annotator", schema="FrameList",
                                   params=[_q("video_id"), _q("state", "string", "ingested, prefiltered, approved, …"),
                                           _q("limit", desc="1..500, default 100"), _q("offset"), *_CURSORS])},
            "/videos": {
                "get": _op("List videos with their frame counts, newest first", "annotator", schema="VideoList",
                           params=[_q("limit", desc="1..1000, default 100"), *_CURSORS]),
                "post": _op("Upload a video (multipart: file, fps, source, illusion_type…); starts an ingest job",
                            "curator", body="VideoUpload", body_type="multipart/form-data", ok="202", schema="UploadJob",
                            errors=_QUEUE_DOWN),
            },
            "/prefilter": {"post": _op("Queue VLM prefilter jobs for unclaimed ingested frames", "curator",
                                       body="PrefilterRequest", ok="202", schema="JobBatch", errors=_QUEUE_DOWN)},
            "/review/frames": {"get": _op(
                "Frames to review with VLM answers and figures", "curator", schema="ReviewPage",
                params=[_q("video_id"), _q("state", "string", "prefiltered (default), approved, rejected, all"),
                        _q("keep", "string", "VLM verdict: true, false, null"), _q("question", desc="1..12, with answer"),
                        _q("answer", "string", "yes, no, unknown"), _q("limit", desc="1..500, default 60"), _q("offset"),
                        *_CURSORS])},
            "/frames/{frame_id}/review": {"post": _op(
                "Approve, reject (with a reason) or reset a frame; 409 if it changed", "curator",
                params=[_FRAME_ID], body="ReviewDecision", schema="ReviewItem",
                errors={"409": "the frame changed since `revision`, or is in no state to review; the answer's "
                               "`frame` is the frame as it is now"})},
            "/queue/annotate/next": {"post": _op(
                "Lease the next approved frame to the caller (404 when none are left)", "annotator", schema="Lease",
                errors={"404": "no approved frames are waiting for annotation",
                        # taking a frame queues the embeddings of it and the next ones
                        **_QUEUE_DOWN})},
            "/frames/{frame_id}": {"get": _op("A frame with its annotation, lease and neighbours", "annotator",
                                              params=[_FRAME_ID], schema="FrameDetail")},
            "/frames/{frame_id}/lease": {"post": _op(
                "Take or renew the caller's lease (409: someone else holds it)", "annotator", params=[_FRAME_ID],
                schema="Lease", errors={"409": "someone else holds the frame, or it is not approved", **_QUEUE_DOWN})},
            "/frames/{frame_id}/lease/release": {"post": _op(
                "Give the frame back to the queue (`released`: false when the caller held no lease)", "annotator",
                params=[_FRAME_ID], schema="LeaseRelease", errors={"409": "someone else holds the frame's lease"})},
            "/frames/{frame_id}/segment": {"post": _op("Clicks (and a box) → a mask as COCO RLE", "annotator",
                                                       params=[_FRAME_ID], body="SegmentRequest", schema="SegmentResult")},
            "/frames/{frame_id}/annotation": {"post": _op(
                "Save (submit=false: a draft) or submit the regions; a stale version is a 409", "annotator",
                params=[_FRAME_ID], body="AnnotationSave", schema="AnnotationSaved",
                errors={"409": "the annotation changed since `version`, someone else holds the frame, or it is not "
                               "approved; nothing was written. Or a submit of a frame that cannot become a sample: "
                               "the regions are saved as a draft, and the answer (an AnnotationSaved with `error` "
                               "and `sample_blocker`) says why",
                        "503": "submitting queues the sample's generation, and the job queue is unreachable: nothing "
                               "was written; try again in a minute"})},
            "/frames/{frame_id}/proposals/{proposal_id}/reject": {"post": _op(
                "Turn a pending proposal of the frame down (409: someone else holds the frame)", "annotator",
                params=[_FRAME_ID, _PROPOSAL_ID], schema="ProposalFate",
                errors={"409": "the caller holds no lease on the frame, or it is no longer being annotated"})},
            "/frames/{frame_id}/delete": {"post": _op(
                "Mark the frame redundant or imperceptible", "annotator", params=[_FRAME_ID], body="DeleteFrame",
                schema="FrameState", errors={"409": "someone else holds the frame, or it is not approved"})},
            "/frames/{frame_id}/propagate": {"post": _op(
                "Carry a region's mask to the next frames as drafts (a job)", "annotator",
                params=[_FRAME_ID], body="Propagate", ok="202", schema="Job", errors=_QUEUE_DOWN)},
            "/review/bulk": {"post": _op("Review many frames; each item succeeds or fails on its own", "curator",
                                         body="BulkReview", schema="BulkResults")},
            "/samples": {"get": _op("Generated samples with QA figures", "annotator", schema="SampleList",
                                    params=[_q("state", "string", "generated, accepted, rejected"),
                                            _q("flagged", "string", "true or false"), _q("limit"), _q("offset"), *_CURSORS,
                                            *_BY_ERROR],
                                    errors={"404": "`evaluation` names no evaluation"})},
            "/samples/{sample_id}": {"get": _op("One sample: files, parameters, provenance, QA", "annotator",
                                                params=[_SAMPLE_ID], schema="Sample")},
            "/samples/{sample_id}/review": {"post": _op(
                "Accept (joins the dataset) or reject (back to annotators) a sample", "curator",
                params=[_SAMPLE_ID], body="SampleDecision", schema="Sample",
                errors={"409": "the sample is not of the frame's current annotation, or its frame moved on"})},
            "/samples/{sample_id}/regenerate": {"post": _op("Generate the sample again (a job)", "curator",
                                                            params=[_SAMPLE_ID], ok="202", schema="Job",
                                                            errors=_QUEUE_DOWN)},
            "/stats/funnel": {"get": _op("Pipeline funnel counts", "annotator", schema="Funnel")},
            "/stats/proposers": {"get": _op("Per proposer: frames, proposals by fate, acceptance rate, median IoU, "
                                            "misses", "annotator", schema="ProposerStats")},
            "/jobs": {"get": _op("List jobs (annotators: their own)", "annotator", schema="JobList",
                                 params=[_q("state", "string"), _q("kind", "string", "one job kind (ingest, generate, train, …)"),
                                         _q("mine", "string", "1: only the jobs the caller launched"),
                                         _q("limit", desc="1..500, default 50"), *_CURSORS])},
            "/jobs/{job_id}": {"get": _op("One job with its log", "annotator", params=[_JOB_ID], schema="Job")},
            "/generate/retry-failed": {"post": _op(
                "Queue again every failed generate job of an annotated frame that can become a sample now (its "
                "cause fixed); the others are named with the reason", "curator", schema="GenerateRetry",
                errors=_QUEUE_DOWN)},
            "/jobs/{job_id}/retry": {"post": _op(
                "Retry a failed or interrupted job (a training job: admins, and it resumes the run)", "curator",
                params=[_JOB_ID], ok="202", schema="Job",
                errors={"403": "a training job, and the caller is not an admin",
                        "409": "the job did not fail and was not interrupted (a run: it cannot resume now)",
                        **_QUEUE_DOWN})},
            "/runs": {
                "get": _op("Training runs, newest first (and the current model)", "curator", schema="RunList",
                           params=[_q("ids", "string", "comma-separated run ids (the compare page)")]),
                "post": _op("Launch a training run on the train queue; an empty selection is a 400 with the reason",
                            "admin", body="RunLaunch", ok="202", schema="Run", errors=_QUEUE_DOWN),
            },
            "/runs/estimate": {"post": _op(
                "How long a launch would train: the nearest finished run's measured step time of the same preset, "
                "scaled by batch × crop pixels × iterations (nothing is launched)", "admin", body="RunLaunch",
                schema="RunEstimate")},
            "/runs/{run_id}": {"get": _op("One run with config, dataset version, splits and checkpoints", "curator",
                                          params=[_RUN_ID], schema="Run")},
            "/runs/{run_id}/metrics": {"get": _op("Curve points after step `after` (live charts)", "curator",
                                                  params=[_RUN_ID, _q("after", desc="training step; default -1: all"),
                                                          _q("after_val", desc="validation step; default -1: all")],
                                                  schema="RunMetrics")},
            "/runs/{run_id}/cancel": {"post": _op("Stop a queued or running run (its whole process group)", "admin",
                                                  params=[_RUN_ID], ok="202", schema="Run",
                                                  errors={"409": "the run is neither queued nor running"})},
            "/runs/{run_id}/resume": {"post": _op(
                "Continue an interrupted, failed or cancelled run from its newest checkpoint", "admin",
                params=[_RUN_ID], ok="202", schema="Run",
                errors={"409": "the run is in no state to resume, or its trainers are still stopping", **_QUEUE_DOWN})},
            "/runs/{run_id}/promote": {"post": _op("Make a checkpoint of the run the current model", "admin",
                                                   params=[_RUN_ID], body="Promote", schema="CurrentModel")},
            "/evaluations": {
                "get": _op("Evaluations, newest first, with their job's state and progress", "curator",
                           schema="EvaluationList"),
                "post": _op("Queue an evaluate job on a dataset folder or a run's test split", "curator",
                            body="EvaluationLaunch", ok="202", schema="Evaluation", errors=_QUEUE_DOWN),
            },
            "/evaluations/{evaluation_id}": {"get": _op("One evaluation and its headline table", "curator",
                                                        params=[_EVALUATION_ID], schema="Evaluation")},
            "/evaluations/{evaluation_id}/files/{name}": {"get": _op(
                "A file of the report folder (report.json, per_sample.csv, index.html, pictures/…, predictions/…)",
                "curator", params=[_EVALUATION_ID, {"name": "name", "in": "path", "required": True,
                                                    "schema": {"type": "string"}}], files=_REPORT_FILES,
                errors={"404": "no such evaluation, no report yet, or no such file in its report folder"})},
            "/runs/{run_id}/checkpoints/{name}": {"get": _op(
                "Download a checkpoint file", "curator", params=[_RUN_ID, _CHECKPOINT], files=("application/octet-stream",),
                errors={"404": "no such run, or no checkpoint of that name in it"})},
        },
        "components": {
            "securitySchemes": {
                "bearer": {"type": "http", "scheme": "bearer", "description": "`illusion-studio users token NAME`"},
                "session": {"type": "apiKey", "in": "cookie", "name": "session",
                            "description": "Browser session; state-changing calls also need the X-CSRFToken header."},
            },
            "schemas": {
                "Error": {"type": "object", "required": ["error", "status"], "properties": {
                    "error": {"type": "string"}, "status": {"type": "integer"},
                    "field": {"type": "string", "description": "a launch's field at fault (with `reason`)"},
                    "reason": {"type": "string"},
                    "frame": {"description": "a review's 409: the frame as it is now", **_ref("ReviewItem")}}},
                "User": {"type": "object", "properties": {"id": {"type": "integer"}, "name": {"type": "string"},
                                                          "role": {"enum": ["annotator", "curator", "admin"]}}},
                "UserList": _list("User"),
                "NewUser": {"type": "object", "required": ["name", "role", "password"],
                            "properties": {"name": {"type": "string"}, "role": {"enum": ["annotator", "curator", "admin"]},
                                           "password": {"type": "string", "minLength": MIN_PASSWORD,
                                                        "maxLength": MAX_PASSWORD}}},
                "Frame": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "video_id": {"type": "integer"},
                    "video": {"type": "string", "description": "the video's name"}, "index": {"type": "integer"},
                    "time_s": {"type": "number", "description": "seconds into the video"},
                    "width": {"type": "integer"}, "height": {"type": "integer"}, "state": {"type": "string"},
                    "revision": {"type": "integer"}, "image": {"type": "string", "description": "media key; GET /media/{key}"},
                    "prefilter_keep": {"type": ["boolean", "null"]}, "generate_failed": _GENERATE_FAILED}},
                "FrameList": _list("Frame", **_PAGED),
                "Funnel": {"type": "object", "additionalProperties": {"type": "integer"}},
                "Job": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "kind": {"type": "string"},
                    "state": {"enum": ["queued", "running", "succeeded", "failed", "interrupted", "cancelled"],
                              "description": "cancelled: a training job whose run was cancelled (retry resumes it)"},
                    "progress": {"type": "number", "minimum": 0, "maximum": 1}, "error": {"type": ["string", "null"]},
                    "took_s": {"type": ["number", "null"], "description": "seconds over every attempt"},
                    "result": {}, "log": {"type": "string"}}},
                "PrefilterRequest": {"type": "object", "properties": {
                    "video_id": {"type": "integer"}, "backend": {"enum": ["heuristic", "openai", "transformers"]},
                    "sparse": {"type": "boolean", "description": "the authors' sparse mode"}}},
                "UploadJob": {"allOf": [_ref("Job"), {"type": "object", "properties": {
                    "sample_blocker": _SAMPLE_BLOCKER}}]},
                "GenerateRetry": {"type": "object", "properties": {
                    "retried": {"type": "array", "items": {"type": "integer"}, "description": "the jobs queued again"},
                    "still_blocked": {"type": "array", "items": {"type": "object", "properties": {
                        "reason": {"type": "string"}, "frame_ids": {"type": "array", "items": {"type": "integer"}}}},
                        "description": "frames that still cannot become samples, by the reason"}}},
                "JobBatch": {"type": "object", "properties": {"jobs": {"type": "array", "items": _ref("Job")}}},
                "VideoList": {"type": "object", "properties": {"items": {"type": "array", "items": {"type": "object"}},
                                                               "prev": _PAGED["prev"], "next": _PAGED["next"]}},
                "VideoUpload": {"type": "object", "required": ["file"], "properties": {
                    "file": {"type": "string", "format": "binary"}, "fps": {"type": "number"},
                    "source": {"enum": ["web", "generated", "real_capture"]},
                    "prefilter": {"type": "boolean", "description": "queue the VLM prefilter afterwards (default true)"},
                    "illusion_type": {"type": "array", "items": {"enum": _ILLUSION_TYPES}},
                    "mono": {"type": "array", "items": {"type": "string", "format": "binary"},
                             "description": "the video's per-frame monocular disparities (.npy or .pfm, float HxW, "
                                            "larger = nearer), each named by its frame's index in the decoded video "
                                            "(frame_000012.npy): its frames can then become samples without a "
                                            "depth model"}}},
                "ReviewDecision": {"type": "object", "required": ["decision"], "properties": {
                    "decision": {"enum": ["approve", "reject", "reset"]}, "reason": {"type": "string", "maxLength": 256},
                    "revision": {"type": "integer", "description": "the frame revision the curator saw; stale → 409"}}},
                "ReviewItem": {"allOf": [_ref("Frame"), {"type": "object", "properties": {
                    "thumb": {"type": "string"}, "prefilter": {"type": ["object", "null"]},
                    "last_review": {"type": ["object", "null"]},
                    "sample_blocker": {**_SAMPLE_BLOCKER, "description": "in the review grid's items: "
                                                                          + _SAMPLE_BLOCKER["description"]}}}]},
                "ReviewPage": _list("ReviewItem", **_PAGED, reasons={"type": "array"}, questions={"type": "array"},
                                    total_exact={"type": "boolean",
                                                 "description": "false: total is a lower bound (a question filter)"}),
                "BulkReview": {"type": "object", "required": ["decision", "items"], "properties": {
                    "decision": {"enum": ["approve", "reject", "reset"]}, "reason": {"type": "string"},
                    "items": {"type": "array", "items": {"type": "object", "properties": {
                        "id": {"type": "integer"}, "revision": {"type": "integer"}}}}}},
                "BulkResults": {"type": "object", "properties": {"results": {"type": "array", "items": {"type": "object"}}}},
                "JobList": _list("Job", prev=_PAGED["prev"], next=_PAGED["next"]),
                "Sample": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "frame_id": {"type": "integer"},
                    "state": {"enum": ["generated", "accepted", "rejected"]},
                    "flagged": {"type": "boolean"}, "files": {"type": "object", "description": "output name → media key"},
                    "params": {"type": "object"}, "provenance": {"type": "object"}, "qa": {"type": "object"},
                    "rejection": {"type": ["object", "null"], "description": "reason, note, by, at of its rejection"},
                    "replaces": {"type": ["object", "null"], "description": "{id, state}: the frame's sample before it"},
                    "replaced_by": {"type": ["object", "null"], "description": "{id, state}: the frame's sample after it"}}},
                "SampleList": _list("Sample", **_PAGED),
                "SampleDecision": {"type": "object", "required": ["decision"], "properties": {
                    "decision": {"enum": ["accept", "reject"]}, "reason": {"type": "string", "maxLength": 256},
                    "note": {"type": "string", "maxLength": 256, "description": "free text beside a rejection's reason"}}},
                "LeaseRelease": {"type": "object", "properties": {
                    "frame_id": {"type": "integer"}, "released": {"type": "boolean"},
                    "reason": {"type": "string", "description": "why nothing was released"}}},
                "FrameState": {"type": "object", "properties": {"frame_id": {"type": "integer"},
                                                                "state": {"type": "string"}}},
                "AnnotationSaved": {"type": "object", "properties": {
                    "frame_id": {"type": "integer"}, "annotation_version": {"type": "integer"},
                    "submitted": {"type": "boolean"}, "state": {"type": "string", "description": "the frame's"},
                    "sample_blocker": {**_SAMPLE_BLOCKER, "description": "only in a refused submit's 409: why the "
                                                                          "frame cannot become a sample"}}},
                "Lease": {"type": "object", "properties": {"frame_id": {"type": "integer"},
                                                           "lease_expires": {"type": "string", "format": "date-time"},
                                                           "returned_waiting": _RETURNED_WAITING}},
                "FrameDetail": {"allOf": [_ref("Frame"), {"type": "object", "properties": {
                    "annotation_version": {"type": "integer"}, "submitted": {"type": "boolean"},
                    "illusion_type": {"enum": [*_ILLUSION_TYPES, None]}, "regions": {"type": "array", "items": _ref("Region")},
                    "lease": {"type": "object"}, "prev_id": {"type": ["integer", "null"]},
                    "returned": {"type": ["object", "null"], "description": "why a curator sent the frame back: "
                                                                              "sample_id, reason, note, by, at, annotator"},
                    "returned_waiting": _RETURNED_WAITING,
                    "next_id": {"type": ["integer", "null"]}, "embedding_ready": {"type": "boolean"},
                    "proposals": {"type": "array", "items": _ref("Proposal")},
                    "proposals_ready": {"type": "boolean", "description": "every configured proposer has looked"},
                    "proposals_note": {"type": "string", "description": "why there are no proposals (empty if any)"},
                    "sample_blocker": _SAMPLE_BLOCKER,
                    "generate_failed": _GENERATE_FAILED,
                    "failed_elsewhere": {"type": "array", "items": {"type": "object"},
                                         "description": "the caller's other submitted frames whose generate job "
                                                        "failed: frame_id, job_id, error (newest first, at most 5)"}}}]},
                "Proposal": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "source": {"type": "string"}, "score": {"type": "number"},
                    "illusion_type": {"enum": [*_ILLUSION_TYPES, None]}, "guess": {"type": ["string", "null"]},
                    "illusion": {"type": "object", "description": "COCO RLE"},
                    "support": {"type": "object", "description": "COCO RLE"},
                    "fate": {"enum": ["pending", "accepted", "edited", "rejected", "hidden"]},
                    "iou": {"type": ["number", "null"]},
                    "hidden": {"type": "boolean", "description": "scored under its scan's threshold: shown on request"}}},
                "ProposalFate": {"type": "object", "properties": {"id": {"type": "integer"}, "fate": {"type": "string"}}},
                "ProposerStats": {"type": "object", "properties": {"proposers": {
                    "type": "object", "additionalProperties": {"type": "object", "properties": {
                        **_PROPOSER_FIGURES, "by_threshold": {"type": "array", "items": {"type": "object", "properties": {
                            **_PROPOSER_FIGURES, "threshold": {"type": "number"}}}}}}}}},
                "RLE": {"type": "object", "description": "COCO run-length encoding (pycocotools)",
                        "properties": {"size": {"type": "array", "items": {"type": "integer"}}, "counts": {"type": "string"}}},
                "Region": {"type": "object", "required": ["pair", "kind", "mask"], "properties": {
                    "pair": {"type": "integer"}, "kind": {"enum": ["illusion", "support"]}, "mask": _ref("RLE"),
                    "clicks": {"type": "array"},
                    "illusion_type": {"enum": _ILLUSION_TYPES, "description": "the pair's type; default: the annotation's"}}},
                "SegmentRequest": {"type": "object", "required": ["points", "labels"], "properties": {
                    "points": {"type": "array", "items": {"type": "array", "items": {"type": "number"}},
                               "description": "[[x, y], …] in full-resolution pixels"},
                    "labels": {"type": "array", "items": {"enum": [0, 1]}},
                    "box": {"type": "array", "items": {"type": "number"}, "description": "[x0, y0, x1, y1]"},
                    "region_kind": {"enum": ["illusion", "support"]}, "prev_mask": _ref("RLE")}},
                "SegmentResult": {"type": "object", "properties": {
                    "mask": _ref("RLE"), "score": {"type": "number"}, "embedding_cached": {"type": "boolean"},
                    "model_id": {"type": "string"}, "area": {"type": "integer"}}},
                "AnnotationSave": {"type": "object", "required": ["version", "regions"], "properties": {
                    "version": {"type": "integer"}, "regions": {"type": "array", "items": _ref("Region")},
                    "illusion_type": {"enum": _ILLUSION_TYPES}, "submit": {"type": "boolean", "default": True}}},
                "Run": {"type": "object", "properties": {
                    "run": {"type": "integer"}, "job": {"type": ["integer", "null"]},
                    "state": {"enum": ["queued", "running", "succeeded", "failed", "diverged", "cancelled",
                                       "interrupted"]},
                    "preset": {"type": "string"}, "step": {"type": "integer"}, "steps": {"type": "integer"},
                    "checkpoint": {"type": ["string", "null"], "description": "the newest step checkpoint (a path)"},
                    "best_checkpoint": {"type": ["string", "null"]},
                    "resumed_from_step": {"type": ["integer", "null"], "description": "null for a fresh run"},
                    "loss": {"type": ["number", "null"]}, "lr": {"type": ["number", "null"]},
                    "samples_per_s": {"type": ["number", "null"]}, "eta_s": {"type": ["number", "null"]},
                    "best_val_epe": {"type": ["number", "null"], "description": "pixels"},
                    "dataset": {"type": "object", "description": "id, samples, kinds (counts), splits (counts)"},
                    "reason": {"type": ["string", "null"]}, "current": {"type": "boolean"}}},
                "RunList": {"type": "object", "properties": {"items": {"type": "array", "items": _ref("Run")},
                                                             "current": {"type": ["object", "null"]}}},
                "RunEstimate": {"type": "object", "properties": {
                    "seconds": {"type": ["number", "null"], "description": "null: no finished run of the preset measured one"},
                    "text": {"type": "string", "description": "the estimate and how it was made, in words"},
                    "run": {"type": ["integer", "null"], "description": "the measured run it scales"},
                    "scale": {"type": ["number", "null"], "description": "batch × pixels × iterations, over the run's"}}},
                "RunMetrics": {"type": "object", "properties": {
                    "run": {"type": "integer"},
                    "step": {"type": "array", "items": {"type": "object", "description": "step, loss, lr, samples_per_s"}},
                    "val": {"type": "array", "items": {"type": "object", "description": "step, metrics, images"}}}},
                "Evaluation": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "job": {"type": ["integer", "null"]}, "state": {"type": "string"},
                    "progress": {"type": ["number", "null"]}, "error": {"type": ["string", "null"]},
                    "dataset": {"type": "string"}, "format": {"type": "string"},
                    "methods": {"type": "array", "items": {"type": "string"}}, "resolution": {"type": "string"},
                    "checkpoint": {"type": ["string", "null"], "description": "run · file, step (never a path)"},
                    "run": {"type": ["integer", "null"]}, "step": {"type": ["integer", "null"]},
                    "summary": {"type": "object", "description": "samples, failed, headline: method → region → {epe, bad2}"},
                    "has_results": {"type": "boolean", "description": "per-sample rows for the Samples pages"}}},
                "EvaluationList": _list("Evaluation"),
                "Promote": {"type": "object", "additionalProperties": False, "properties": {"checkpoint": {
                    "type": "string", "description": "best (default), last, or a file name from the run's checkpoints"}}},
                # The launch schemas, as the API validates them (model/runs/schema.py).
                **openapi_schemas(),
                "CurrentModel": {"type": "object", "properties": {
                    "run": {"type": ["integer", "null"]}, "file": {"type": "string"}, "step": {"type": ["integer", "null"]},
                    "best": {"type": "boolean"}}},
                "DeleteFrame": {"type": "object", "properties": {"reason": {"enum": ["redundant", "imperceptible"]}}},
                "Propagate": {"type": "object", "required": ["pair", "kind", "mask"], "properties": {
                    "pair": {"type": "integer"}, "kind": {"enum": ["illusion", "support"]}, "mask": _ref("RLE"),
                    "count": {"type": "integer", "minimum": 1, "maximum": 100}}},
            },
        },
    }
