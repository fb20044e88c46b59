"""List and queue routes at the paper's scale: p50/p95 of every grid, queue and page over HTTP with
N frames seeded, beside the same routes at N/10, on SQLite and (given a server) PostgreSQL.

The seed follows the paper's funnel (1.4M prefiltered frames, ~236k kept, ~176k annotated): most
frames wait for curators, a fifth are rejected, about one in seven has been kept and annotated and
has a sample; every frame past ingest has a verdict (one in ten two), every curated one a decision
(one in twenty two), and the prefilter ran as one job per 32 frames. Rows go in with bulk inserts
(executemany on SQLite, COPY on PostgreSQL) into the schema of migration 0001, and then the real
``alembic upgrade head`` runs over the populated database — so the figures include what migrating a
real workspace costs. The server is ``illusion-studio serve`` in its own process, as in production.
"""

from __future__ import annotations

import json
import random
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from alembic import command
from sqlalchemy import Connection, text

from benchmarks.served import served_app
from dataset.db import alembic_config, make_engine, make_session_factory, scratch_database, transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from dataset.services.prefilter import launch_prefilter
from dataset.settings import write_settings_file
from dataset.tables import User

FRAMES_PER_VIDEO = 1000
CHUNK_VIDEOS = 20  # videos generated and inserted per round trip
BENCH_DATABASE = "bench_scale"
# (state, share of frames): a snapshot of the paper's funnel mid-curation.
_STATES = (("ingested", 0.04), ("prefiltered", 0.56), ("rejected", 0.22), ("approved", 0.04),
           ("annotated", 0.01), ("generated", 0.015), ("accepted", 0.11), ("deleted", 0.005))
_CURATED = {"approved", "annotated", "generated", "accepted", "deleted"}
_T0 = datetime(2026, 1, 1)


def run_scale_bench(frames: int, database_url: str | None = None, repeats: int = 20) -> dict[str, Any]:
    """Per backend: route p50/p95 at ``frames`` and at ``frames // 10``, seed and upgrade seconds,
    and the prefilter's claim of the whole ingested backlog."""
    backends: dict[str, Any] = {}
    targets = [("sqlite", None)] + ([("postgresql", database_url)] if database_url else [])
    for name, server_url in targets:
        result: dict[str, Any] = {}
        for n, label in ((max(frames // 10, FRAMES_PER_VIDEO), "tenth"), (frames, "full")):
            with tempfile.TemporaryDirectory() as tmp, _database(name, server_url, Path(tmp)) as url:
                measured = _measure(Path(tmp), url, n, repeats)
            if label == "full":
                result.update(measured)
            else:
                result["tenth"] = {"frames": n, "routes": measured["routes"]}
        backends[name] = result
    return {"frames": frames, "repeats": repeats, "backends": backends}


@contextmanager
def _database(backend: str, server_url: str | None, tmp: Path) -> Iterator[str]:
    """A database of the bench's own: a file, or ``bench_scale`` created (and dropped) on the server."""
    if backend == "sqlite":
        yield f"sqlite:///{tmp / 'illusion-studio.db'}"
        return
    with scratch_database(server_url or "", BENCH_DATABASE) as url:
        yield url


def _measure(home: Path, url: str, n: int, repeats: int) -> dict[str, Any]:
    cfg = alembic_config(url)
    command.upgrade(cfg, "0001")
    engine = make_engine(url)
    started = time.perf_counter()
    with engine.begin() as conn:
        seeded = seed(conn, n)
    seed_s = time.perf_counter() - started
    started = time.perf_counter()
    command.upgrade(cfg, "head")
    upgrade_s = time.perf_counter() - started
    if engine.dialect.name == "postgresql":  # what autovacuum does after a bulk load
        with engine.connect().execution_options(isolation_level="AUTOCOMMIT") as conn:
            conn.execute(text("VACUUM ANALYZE"))
    sessions = make_session_factory(engine)
    with transaction(sessions) as s:
        tokens = {role: user_service.issue_token(s, s.get(User, uid)) for role, uid in seeded["users"].items()}
    write_settings_file(home, database_url=url)
    routes = _time_routes(home, tokens, seeded, repeats)
    claim = _time_claim(sessions)
    engine.dispose()
    return {"routes": routes, "seed_s": round(seed_s, 1), "upgrade_s": round(upgrade_s, 1), "prefilter_claim": claim,
            "counts": seeded["counts"]}


# --- seeding ----------------------------------------------------------------------------------

def seed(conn: Connection, n: int, seed_value: int = 0) -> dict[str, Any]:
    """Insert ``n`` frames (and their videos, verdicts, decisions, annotations, samples, jobs) into a
    database at revision 0001; returns the users' ids and the row counts."""
    rng = random.Random(seed_value)
    now = _T0.isoformat(sep=" ")
    users = {"curator": 1, "annotator": 2}
    _bulk(conn, "users", ("id", "name", "password_hash", "role", "active", "created_at"),
          [(1, "curator", "!", "curator", True, now), (2, "annotator", "!", "annotator", True, now)])
    names, shares = zip(*_STATES, strict=True)
    ids = {"frame": 0, "result": 0, "review": 0, "annotation": 0, "sample": 0, "job": 0}
    counts = dict.fromkeys(ids, 0)
    videos = -(-n // FRAMES_PER_VIDEO)
    for first in range(0, videos, CHUNK_VIDEOS):
        rows: dict[str, list[tuple[Any, ...]]] = {t: [] for t in ("videos", "frames", "prefilter_results", "reviews",
                                                                    "annotations", "samples", "jobs")}
        for v in range(first, min(first + CHUNK_VIDEOS, videos)):
            _seed_video(rng, v, min(FRAMES_PER_VIDEO, n - v * FRAMES_PER_VIDEO), names, shares, ids, rows)
        for table, values in rows.items():
            _bulk(conn, table, _COLUMNS[table], values)
    for key in counts:
        counts[key] = ids[key]
    if conn.dialect.name == "postgresql":  # the rows came with their ids: move the sequences past them
        for table in ("users", "videos", "frames", "prefilter_results", "reviews", "annotations", "samples", "jobs"):
            conn.execute(text(f"SELECT setval(pg_get_serial_sequence('{table}', 'id'), "
                              f"(SELECT coalesce(max(id), 1) FROM {table}))"))
    return {"users": users, "counts": counts, "videos": videos}


_COLUMNS: dict[str, tuple[str, ...]] = {
    "videos": ("id", "name", "source_kind", "illusion_types", "content_sha256", "original_path", "fps", "width",
               "height", "meta", "created_at"),
    "frames": ("id", "video_id", "index", "time_s", "width", "height", "content_sha256", "media_key", "state",
               "revision", "assets", "prefilter_job_id", "updated_at"),
    "prefilter_results": ("id", "frame_id", "backend", "model_id", "prompt_version", "raw_answer", "answers", "parsed",
                          "keep", "reason", "metrics", "created_at"),
    "reviews": ("id", "frame_id", "user_id", "decision", "reason", "created_at"),
    "annotations": ("id", "frame_id", "user_id", "version", "illusion_type", "submitted", "created_at", "updated_at"),
    "samples": ("id", "frame_id", "annotation_version", "state", "flagged", "files", "params", "provenance", "qa",
                "created_at"),
    "jobs": ("id", "kind", "state", "progress", "params", "result", "log", "attempts", "created_by_id", "created_at",
             "finished_at"),
}
_KINDS = ("picture", "inpainting", "replay", "holography", "mirror")


def _seed_video(rng: random.Random, v: int, count: int, names: Sequence[str], shares: Sequence[float],
                ids: dict[str, int], rows: dict[str, list[tuple[Any, ...]]]) -> None:
    vid = v + 1
    at = (_T0 + timedelta(minutes=v)).isoformat(sep=" ")
    rows["videos"].append((vid, f"video-{vid:06d}.mp4", "web", json.dumps([_KINDS[v % 5]]), f"{vid:064x}", "", 2.0,
                           1920, 1080, "{}", at))
    states = rng.choices(names, weights=shares, k=count)
    frame_ids = []
    for index, state in enumerate(states):
        ids["frame"] += 1
        fid = ids["frame"]
        frame_ids.append(fid)
        rows["frames"].append((fid, vid, index, index / 2, 1920, 1080, f"{fid:064x}", f"ab/{fid:062x}.jpg", state,
                               1 if state == "ingested" else 2 + (state in _CURATED), json.dumps({"thumb": f"t/{fid}.jpg"}),
                               None, at))
        if state == "ingested":
            continue
        for attempt in range(1 + (rng.random() < 0.1)):  # one in ten was asked again with a newer prompt
            ids["result"] += 1
            answers = [rng.choice((True, False, None)) for _ in range(12)]
            keep = False if state == "rejected" and rng.random() < 0.7 else (
                True if state in _CURATED or rng.random() < 0.7 else None)
            rows["prefilter_results"].append((
                ids["result"], fid, "openai", "Qwen2-VL-72B-Instruct", f"paper-v{attempt + 1}",
                " ".join("yes" if a else "no" if a is False else "unknown" for a in answers), json.dumps(answers),
                True, keep, "Q1 yes; Q9 no", json.dumps({"laplacian_var": round(rng.uniform(10, 900), 1)}), at))
        if state in _CURATED or (state == "rejected" and rng.random() < 0.3):
            for redo in range(1 + (rng.random() < 0.05)):
                ids["review"] += 1
                rows["reviews"].append((ids["review"], fid, 1, "reject" if state == "rejected" and redo == 0 else "approve",
                                        "blurry" if state == "rejected" else "", at))
        submitted = state in ("annotated", "generated", "accepted")
        if submitted or (state == "approved" and rng.random() < 0.2):
            ids["annotation"] += 1
            version = 1 + (rng.random() < 0.1)
            rows["annotations"].append((ids["annotation"], fid, 2, version, _KINDS[fid % 5], submitted, at, at))
            if state in ("generated", "accepted"):
                for older in ([version - 1] if version > 1 else []) + [version]:
                    ids["sample"] += 1
                    sample_state = "rejected" if older < version else ("accepted" if state == "accepted" else "generated")
                    rows["samples"].append((ids["sample"], fid, older, sample_state, rng.random() < 0.05,
                                            json.dumps({"left": f"l/{fid}.png", "right": f"r/{fid}.png"}),
                                            '{"tau": 0.9}', '{"git": "bench"}', '{"hole_fraction": 0.05}', at))
                    rows["jobs"].append(_job(ids, "generate", {"frame_id": fid, "annotation_version": older}, at))
    for start in range(0, len(frame_ids), 32):  # the prefilter's chunk jobs
        rows["jobs"].append(_job(ids, "prefilter", {"frame_ids": frame_ids[start:start + 32], "backend": "openai"}, at))


def _job(ids: dict[str, int], kind: str, params: dict[str, Any], at: str) -> tuple[Any, ...]:
    ids["job"] += 1
    state = "failed" if ids["job"] % 97 == 0 else "succeeded"
    return (ids["job"], kind, state, 1.0, json.dumps(params), "{}", f"{kind}: done\n", 1, 1, at, at)


def _bulk(conn: Connection, table: str, columns: Sequence[str], rows: list[tuple[Any, ...]]) -> None:
    """COPY on PostgreSQL, one executemany on SQLite."""
    if not rows:
        return
    quoted = ", ".join(f'"{c}"' for c in columns)
    if conn.dialect.name == "postgresql":
        cursor = conn.connection.driver_connection.cursor()
        with cursor.copy(f"COPY {table} ({quoted}) FROM STDIN") as copy:
            for row in rows:
                copy.write_row(row)
        return
    conn.exec_driver_sql(f"INSERT INTO {table} ({quoted}) VALUES ({', '.join('?' * len(columns))})", rows)


# --- timing -----------------------------------------------------------------------------------

def _routes(client: httpx.Client, seeded: dict[str, Any]) -> dict[str, tuple[str, str, str]]:
    """Route label → (method, path, role); cursors for the deep pages come from untimed calls."""
    n = seeded["counts"]["frame"]
    deep = {}
    for key, path in (("review", "/api/v1/review/frames?limit=1"), ("frames", "/api/v1/frames?state=prefiltered&limit=1")):
        deep[key] = client.get(f"{path}&offset={int(n * 0.5)}").json()["next"]
    video = seeded["videos"] // 2 + 1
    return {
        "GET /api/v1/review/frames?limit=60": ("GET", "/api/v1/review/frames?limit=60", "curator"),
        "GET /api/v1/review/frames?after=(deep)": ("GET", f"/api/v1/review/frames?limit=60&after={deep['review']}", "curator"),
        "GET /api/v1/review/frames?offset=50000": ("GET", "/api/v1/review/frames?limit=60&offset=50000", "curator"),
        "GET /api/v1/review/frames?state=all": ("GET", "/api/v1/review/frames?limit=60&state=all", "curator"),
        "GET /api/v1/review/frames?keep=false": ("GET", "/api/v1/review/frames?limit=60&keep=false", "curator"),
        "GET /api/v1/review/frames?state=approved&keep=true": (
            "GET", "/api/v1/review/frames?limit=60&state=approved&keep=true", "curator"),
        "GET /api/v1/review/frames?question=9&answer=yes": (
            "GET", "/api/v1/review/frames?limit=60&question=9&answer=yes", "curator"),
        "GET /api/v1/review/frames?video_id=V": ("GET", f"/api/v1/review/frames?limit=60&video_id={video}", "curator"),
        "GET /api/v1/frames?limit=100": ("GET", "/api/v1/frames?limit=100", "curator"),
        "GET /api/v1/frames?state=prefiltered&offset=50000": (
            "GET", "/api/v1/frames?state=prefiltered&offset=50000", "curator"),
        "GET /api/v1/frames?state=prefiltered&after=(deep)": (
            "GET", f"/api/v1/frames?state=prefiltered&after={deep['frames']}", "curator"),
        "GET /api/v1/samples?limit=60": ("GET", "/api/v1/samples?limit=60", "curator"),
        "GET /api/v1/samples?state=generated&flagged=true": (
            "GET", "/api/v1/samples?limit=60&state=generated&flagged=true", "curator"),
        "GET /api/v1/videos": ("GET", "/api/v1/videos", "curator"),
        "GET /api/v1/jobs?limit=50": ("GET", "/api/v1/jobs?limit=50", "curator"),
        "GET /api/v1/jobs?state=failed": ("GET", "/api/v1/jobs?state=failed", "curator"),
        "GET /api/v1/stats/funnel": ("GET", "/api/v1/stats/funnel", "curator"),
        "POST /api/v1/queue/annotate/next": ("POST", "/api/v1/queue/annotate/next", "annotator"),
        "GET / (dashboard)": ("GET", "/", "curator"),
        "GET /review": ("GET", "/review", "curator"),
        "GET /frames": ("GET", "/frames", "curator"),
        "GET /samples": ("GET", "/samples", "curator"),
        "GET /jobs": ("GET", "/jobs", "curator"),
    }


def _time_routes(home: Path, tokens: dict[str, str], seeded: dict[str, Any], repeats: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    with served_app(home) as base_url:
        clients = {role: httpx.Client(base_url=base_url, headers={"Authorization": f"Bearer {token}"}, timeout=600)
                   for role, token in tokens.items()}
        try:
            for label, (method, path, role) in _routes(clients["curator"], seeded).items():
                client, times = clients[role], []
                for attempt in range(repeats + 1):  # the first call is untimed: it warms the server's caches
                    start = time.perf_counter()
                    response = client.request(method, path)
                    elapsed = (time.perf_counter() - start) * 1000
                    if response.status_code != 200:
                        raise RuntimeError(f"{label}: HTTP {response.status_code}: {response.text[:200]}")
                    if attempt:
                        times.append(elapsed)
                    if label.startswith("POST /api/v1/queue"):  # give it back, so each call searches the queue
                        client.post(f"/api/v1/frames/{response.json()['frame_id']}/lease/release")
                out[label] = {"p50_ms": round(float(np.percentile(times, 50)), 1),
                              "p95_ms": round(float(np.percentile(times, 95)), 1)}
        finally:
            for client in clients.values():
                client.close()
    return out


def _time_claim(sessions: Any) -> dict[str, Any]:
    """The prefilter claiming the whole ingested backlog in chunk jobs (rolled back afterwards)."""
    jobs: list[int] = []

    def submit(session: Any, kind: str, params: dict[str, Any], user: Any) -> Any:
        job = job_service.create_job(session, kind, params, user)
        jobs.append(len(params["frame_ids"]))
        return job

    with sessions() as s:
        started = time.perf_counter()
        launch_prefilter(s, submit, None)
        seconds = time.perf_counter() - started
        s.rollback()
    return {"frames": sum(jobs), "jobs": len(jobs), "seconds": round(seconds, 2)}

