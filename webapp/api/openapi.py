"""The OpenAPI 3.1 description of ``/api/v1`` (a test keeps it and the routes in step)."""

from __future__ import annotations

from typing import Any

from dataset.models import IllusionType
from model.launch import openapi_schemas


def _ref(name: str) -> dict[str, str]:
    return {"$ref": f"#/components/schemas/{name}"}


def _json(schema: dict[str, Any]) -> dict[str, Any]:
    return {"application/json": {"schema": schema}}


def _list(name: str, **extra: Any) -> dict[str, Any]:
    """An object whose ``items`` are ``name`` schemas (and ``extra`` properties)."""
    return {"type": "object", "properties": {"items": {"type": "array", "items": _ref(name)}, **extra}}


_ERR = {"description": "error", "content": _json(_ref("Error"))}


def _op(summary: str, role: str, *, params: list[dict[str, Any]] | None = None,
        body: str | None = None, ok: str = "200", schema: str | None = None) -> dict[str, Any]:
    op: dict[str, Any] = {
        "summary": summary,
        "description": f"Needs the **{role}** role (or higher).",
        "parameters": params or [],
        "responses": {
            ok: {"description": "success", "content": _json(_ref(schema))} if schema else {"description": "success"},
            "401": _ERR, "403": _ERR,
        },
    }
    if body:
        op["requestBody"] = {"required": True, "content": _json(_ref(body))}
        op["responses"]["400"] = _ERR
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
_RUN_ID = {"name": "run_id", "in": "path", "required": True, "schema": {"type": "integer"}}
_CHECKPOINT = {"name": "name", "in": "path", "required": True, "schema": {"type": "string"},
               "description": "a file name from the run's checkpoints (best.pt, step_0001000.pt, …)"}


def openapi_document() -> dict[str, Any]:
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
                "post": _op("Create a user", "admin", body="NewUser", ok="201", schema="User"),
            },
            "/frames": {"get": _op("List frames, ordered by video and time", "annotator", schema="FrameList",
                                   params=[_q("video_id"), _q("state", "string", "ingested, prefiltered, approved, …"),
                                           _q("limit", desc="1..10000, default 100"), _q("offset"), *_CURSORS])},
            "/videos": {
                "get": _op("List videos with their frame counts, newest first", "annotator", schema="VideoList",
                           params=[_q("limit", desc="1..1000, default 100"), *_CURSORS]),
                "post": _op("Upload a video (multipart: file, fps, source, illusion_type…); starts an ingest job",
                            "curator", body="VideoUpload", ok="202", schema="Job"),
            },
            "/prefilter": {"post": _op("Queue VLM prefilter jobs for unclaimed ingested frames", "curator",
                                       body="PrefilterRequest", ok="202", schema="JobBatch")},
            "/review/frames": {"get": _op(
                "Frames to review with VLM answers and figures", "curator", schema="ReviewPage",
                params=[_q("video_id"), _q("state", "string", "prefiltered (default), approved, rejected, all"),
                        _q("keep", "string", "VLM verdict: true, false, null"), _q("question", desc="1..12, with answer"),
                        _q("answer", "string", "yes, no, unknown"), _q("limit", desc="1..500, default 60"), _q("offset"),
                        *_CURSORS])},
            "/frames/{frame_id}/review": {"post": _op(
                "Approve, reject (with a reason) or reset a frame; 409 if it changed", "curator",
                params=[_FRAME_ID], body="ReviewDecision", schema="ReviewItem")},
            "/queue/annotate/next": {"post": _op(
                "Lease the next approved frame to the caller (404 when none are left)", "annotator", schema="Lease")},
            "/frames/{frame_id}": {"get": _op("A frame with its annotation, lease and neighbours", "annotator",
                                              params=[_FRAME_ID], schema="FrameDetail")},
            "/frames/{frame_id}/lease": {"post": _op("Renew the caller's lease (409: someone else holds it)", "annotator",
                                                     params=[_FRAME_ID], schema="Lease")},
            "/frames/{frame_id}/lease/release": {"post": _op("Give the frame back to the queue", "annotator",
                                                             params=[_FRAME_ID])},
            "/frames/{frame_id}/segment": {"post": _op("Clicks (and a box) → a mask as COCO RLE", "annotator",
                                                       params=[_FRAME_ID], body="SegmentRequest", schema="SegmentResult")},
            "/frames/{frame_id}/annotation": {"post": _op(
                "Save (submit=false: a draft) or submit the regions; a stale version is a 409", "annotator",
                params=[_FRAME_ID], body="AnnotationSave")},
            "/frames/{frame_id}/proposals/{proposal_id}/reject": {"post": _op(
                "Turn a pending proposal of the frame down (409: someone else holds the frame)", "annotator",
                params=[_FRAME_ID, _PROPOSAL_ID], schema="ProposalFate")},
            "/frames/{frame_id}/delete": {"post": _op("Mark the frame redundant or imperceptible", "annotator",
                                                      params=[_FRAME_ID], body="DeleteFrame")},
            "/frames/{frame_id}/propagate": {"post": _op(
                "Carry a region's mask to the next frames as drafts (a job)", "annotator",
                params=[_FRAME_ID], body="Propagate", ok="202", schema="Job")},
            "/review/bulk": {"post": _op("Review many frames; each item succeeds or fails on its own", "curator",
                                         body="BulkReview", schema="BulkResults")},
            "/samples": {"get": _op("Generated samples with QA figures", "annotator", schema="SampleList",
                                    params=[_q("state", "string", "generated, accepted, rejected"),
                                            _q("flagged", "string", "true or false"), _q("limit"), _q("offset"), *_CURSORS,
                                            *_BY_ERROR])},
            "/samples/{sample_id}": {"get": _op("One sample: files, parameters, provenance, QA", "annotator",
                                                params=[_SAMPLE_ID], schema="Sample")},
            "/samples/{sample_id}/review": {"post": _op(
                "Accept (joins the dataset) or reject (back to annotators) a sample", "curator",
                params=[_SAMPLE_ID], body="SampleDecision", schema="Sample")},
            "/samples/{sample_id}/regenerate": {"post": _op("Generate the sample again (a job)", "curator",
                                                            params=[_SAMPLE_ID], ok="202", schema="Job")},
            "/stats/funnel": {"get": _op("Pipeline funnel counts", "annotator", schema="Funnel")},
            "/stats/proposers": {"get": _op("Per proposer: frames, proposals by fate, acceptance rate, median IoU, "
                                            "misses", "annotator", schema="ProposerStats")},
            "/jobs": {"get": _op("List jobs (annotators: their own)", "annotator", schema="JobList",
                                 params=[_q("state", "string"), _q("limit", desc="1..500, default 50"), *_CURSORS])},
            "/jobs/{job_id}": {"get": _op("One job with its log", "annotator", params=[_JOB_ID], schema="Job")},
            "/jobs/{job_id}/retry": {"post": _op("Retry a failed or interrupted job (a training job: admins, "
                                                 "and it resumes the run)", "curator",
                                                 params=[_JOB_ID], ok="202", schema="Job")},
            "/runs": {
                "get": _op("Training runs, newest first (and the current model)", "curator", schema="RunList",
                           params=[_q("ids", "string", "comma-separated run ids (the compare page)")]),
                "post": _op("Launch a training run on the train queue; an empty selection is a 400 with the reason",
                            "admin", body="RunLaunch", ok="202", schema="Run"),
            },
            "/runs/{run_id}": {"get": _op("One run with config, dataset version, splits and checkpoints", "curator",
                                          params=[_RUN_ID], schema="Run")},
            "/runs/{run_id}/metrics": {"get": _op("Curve points after step `after` (live charts)", "curator",
                                                  params=[_RUN_ID, _q("after", desc="training step; default -1: all"),
                                                          _q("after_val", desc="validation step; default -1: all")],
                                                  schema="RunMetrics")},
            "/runs/{run_id}/cancel": {"post": _op("Stop a queued or running run (its whole process group)", "admin",
                                                  params=[_RUN_ID], ok="202", schema="Run")},
            "/runs/{run_id}/resume": {"post": _op("Continue an interrupted, failed or cancelled run from its newest "
                                                  "checkpoint", "admin", params=[_RUN_ID], ok="202", schema="Run")},
            "/runs/{run_id}/promote": {"post": _op("Make a checkpoint of the run the current model", "admin",
                                                   params=[_RUN_ID], body="Promote", schema="CurrentModel")},
            "/evaluations": {
                "get": _op("Evaluations, newest first, with their job's state and progress", "curator",
                           schema="EvaluationList"),
                "post": _op("Queue an evaluate job on a dataset folder or a run's test split", "curator",
                            body="EvaluationLaunch", ok="202", schema="Evaluation"),
            },
            "/evaluations/{evaluation_id}": {"get": _op("One evaluation and its headline table", "curator",
                                                        params=[_EVALUATION_ID], schema="Evaluation")},
            "/evaluations/{evaluation_id}/files/{name}": {"get": _op(
                "A file of the report folder (report.json, per_sample.csv, pictures/…, predictions/…)", "curator",
                params=[_EVALUATION_ID, {"name": "name", "in": "path", "required": True, "schema": {"type": "string"}}])},
            "/runs/{run_id}/checkpoints/{name}": {"get": _op("Download a checkpoint file", "curator",
                                                             params=[_RUN_ID, _CHECKPOINT])},
        },
        "components": {
            "securitySchemes": {
                "bearer": {"type": "http", "scheme": "bearer", "description": "`illusion-studio users token NAME`"},
                "session": {"type": "apiKey", "in": "cookie", "name": "session",
                            "description": "Browser session; state-changing calls also need the X-CSRFToken header."},
            },
            "schemas": {
                "Error": {"type": "object", "properties": {"error": {"type": "string"}, "status": {"type": "integer"}}},
                "User": {"type": "object", "properties": {"id": {"type": "integer"}, "name": {"type": "string"},
                                                          "role": {"enum": ["annotator", "curator", "admin"]}}},
                "UserList": _list("User"),
                "NewUser": {"type": "object", "required": ["name", "role", "password"],
                            "properties": {"name": {"type": "string"}, "role": {"enum": ["annotator", "curator", "admin"]},
                                           "password": {"type": "string", "minLength": 8}}},
                "Frame": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "video_id": {"type": "integer"},
                    "video": {"type": "string", "description": "the video's name"}, "index": {"type": "integer"},
                    "time_s": {"type": "number", "description": "seconds into the video"},
                    "width": {"type": "integer"}, "height": {"type": "integer"}, "state": {"type": "string"},
                    "revision": {"type": "integer"}, "image": {"type": "string", "description": "media key; GET /media/{key}"},
                    "prefilter_keep": {"type": ["boolean", "null"]}}},
                "FrameList": _list("Frame", **_PAGED),
                "Funnel": {"type": "object", "additionalProperties": {"type": "integer"}},
                "Job": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "kind": {"type": "string"},
                    "state": {"enum": ["queued", "running", "succeeded", "failed", "interrupted"]},
                    "progress": {"type": "number", "minimum": 0, "maximum": 1}, "error": {"type": ["string", "null"]},
                    "result": {}, "log": {"type": "string"}}},
                "PrefilterRequest": {"type": "object", "properties": {
                    "video_id": {"type": "integer"}, "backend": {"enum": ["heuristic", "openai", "transformers"]},
                    "sparse": {"type": "boolean", "description": "the authors' sparse mode"}}},
                "JobBatch": {"type": "object", "properties": {"jobs": {"type": "array", "items": _ref("Job")}}},
                "VideoList": {"type": "object", "properties": {"items": {"type": "array", "items": {"type": "object"}},
                                                               "prev": _PAGED["prev"], "next": _PAGED["next"]}},
                "VideoUpload": {"type": "object", "required": ["file"], "properties": {
                    "file": {"type": "string", "format": "binary"}, "fps": {"type": "number"},
                    "source": {"enum": ["web", "generated", "real_capture"]},
                    "prefilter": {"type": "boolean", "description": "queue the VLM prefilter afterwards (default true)"},
                    "illusion_type": {"type": "array", "items": {"enum": _ILLUSION_TYPES}}}},
                "ReviewDecision": {"type": "object", "required": ["decision"], "properties": {
                    "decision": {"enum": ["approve", "reject", "reset"]}, "reason": {"type": "string", "maxLength": 256},
                    "revision": {"type": "integer", "description": "the frame revision the curator saw; stale → 409"}}},
                "ReviewItem": {"allOf": [_ref("Frame"), {"type": "object", "properties": {
                    "thumb": {"type": "string"}, "prefilter": {"type": ["object", "null"]},
                    "last_review": {"type": ["object", "null"]}}}]},
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
                    "params": {"type": "object"}, "provenance": {"type": "object"}, "qa": {"type": "object"}}},
                "SampleList": _list("Sample", **_PAGED),
                "SampleDecision": {"type": "object", "required": ["decision"], "properties": {
                    "decision": {"enum": ["accept", "reject"]}, "reason": {"type": "string"}}},
                "Lease": {"type": "object", "properties": {"frame_id": {"type": "integer"},
                                                           "lease_expires": {"type": "string", "format": "date-time"}}},
                "FrameDetail": {"allOf": [_ref("Frame"), {"type": "object", "properties": {
                    "annotation_version": {"type": "integer"}, "submitted": {"type": "boolean"},
                    "illusion_type": {"enum": [*_ILLUSION_TYPES, None]}, "regions": {"type": "array", "items": _ref("Region")},
                    "lease": {"type": "object"}, "prev_id": {"type": ["integer", "null"]},
                    "returned": {"type": ["object", "null"], "description": "why a curator sent the frame back: "
                                                                              "sample_id, reason, by, at, annotator"},
                    "next_id": {"type": ["integer", "null"]}, "embedding_ready": {"type": "boolean"},
                    "proposals": {"type": "array", "items": _ref("Proposal")},
                    "proposals_ready": {"type": "boolean", "description": "every configured proposer has looked"},
                    "proposals_note": {"type": "string", "description": "why there are no proposals (empty if any)"}}}]},
                "Proposal": {"type": "object", "properties": {
                    "id": {"type": "integer"}, "source": {"type": "string"}, "score": {"type": "number"},
                    "illusion_type": {"enum": [*_ILLUSION_TYPES, None]}, "guess": {"type": ["string", "null"]},
                    "illusion": {"type": "object", "description": "COCO RLE"},
                    "support": {"type": "object", "description": "COCO RLE"},
                    "fate": {"enum": ["pending", "accepted", "edited", "rejected"]},
                    "iou": {"type": ["number", "null"]}}},
                "ProposalFate": {"type": "object", "properties": {"id": {"type": "integer"}, "fate": {"type": "string"}}},
                "ProposerStats": {"type": "object", "properties": {"proposers": {
                    "type": "object", "additionalProperties": {"type": "object", "properties": {
                        "frames": {"type": "integer"}, "proposals": {"type": "integer"},
                        "pending": {"type": "integer"}, "accepted": {"type": "integer"},
                        "edited": {"type": "integer"}, "rejected": {"type": "integer"},
                        "acceptance_rate": {"type": ["number", "null"]}, "median_iou": {"type": ["number", "null"]},
                        "misses": {"type": "integer"}, "ms_per_frame": {"type": ["number", "null"]}}}}}},
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
                # The launch schemas, as the API validates them (model/launch.py).
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
