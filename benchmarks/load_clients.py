"""The people of ``bench load``: annotators and curators working a served app over real HTTP.

Each client is one person with a connection of their own, logged in through the login form (a
cookie session and a CSRF header, as the pages work) or sending an API token (as scripts do). Every
call is timed under its route's name and tallied by status; every write the server acknowledged is
remembered, so that the bench can look for it in the database afterwards.
"""

from __future__ import annotations

import random
import re
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from typing import Any

import httpx

MAX_REQUESTS = 20_000  # per client: the loop ends at the deadline or here, whichever comes first
SUBMIT_SHARE = 0.3  # the rest of the frames are saved as drafts and given back for someone else to finish
STALE_SHARE = 0.1  # saves sent again with the version they started from, as a double click would
PAGE = 30  # review grid page size
DECISIONS_PER_PAGE = 3
_CSRF = re.compile(r'name="csrf_token"[^>]*value="([^"]+)"|<meta name="csrf-token" content="([^"]+)"')


@dataclass(frozen=True)
class Decision:
    """A review decision the server acknowledged."""

    frame_id: int
    decision: str
    base: int  # the frame revision it was sent with
    revision: int  # the revision it answered


@dataclass(frozen=True)
class Save:
    """An annotation save the server acknowledged."""

    frame_id: int
    base: int  # the annotation version it was sent with
    version: int  # the annotation_version it answered
    masks: tuple[str, ...]  # the regions' RLE counts as sent, in (pair, kind) order
    submitted: bool


@dataclass
class Tally:
    """What one client did and saw."""

    user_id: int
    times: defaultdict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    statuses: Counter[int] = field(default_factory=Counter)
    transport_errors: int = 0
    reviews: list[Decision] = field(default_factory=list)
    saves: list[Save] = field(default_factory=list)
    stale_accepted: int = 0  # a save from an outdated version that got a 2xx: an overwrite

    @property
    def requests(self) -> int:
        return sum(self.statuses.values()) + self.transport_errors


class Client:
    """One person's connection to the app; :meth:`call` times and tallies every request."""

    def __init__(self, base_url: str, tally: Tally, deadline: float) -> None:
        self.http = httpx.Client(base_url=base_url, timeout=120)
        self.tally, self.deadline = tally, deadline

    def working(self) -> bool:
        return time.monotonic() < self.deadline and self.tally.requests < MAX_REQUESTS

    def call(self, method: str, path: str, route: str, **kwargs: Any) -> httpx.Response | None:
        """The response, or None when the connection failed (counted as a transport error)."""
        start = time.perf_counter()
        try:
            response = self.http.request(method, path, **kwargs)
        except httpx.TransportError:
            self.tally.transport_errors += 1
            return None
        self.tally.times[route].append((time.perf_counter() - start) * 1000)
        self.tally.statuses[response.status_code] += 1
        return response

    def use_token(self, token: str) -> None:
        self.http.headers["Authorization"] = f"Bearer {token}"

    def log_in(self, name: str, password: str) -> None:
        """Log in through the form and keep the page's CSRF token for the API's writes."""
        page = self.call("GET", "/login", "GET /login")
        response = self.call("POST", "/login", "POST /login",
                             data={"name": name, "password": password, "csrf_token": _csrf(page)})
        if response is None or response.status_code != 302:
            raise RuntimeError(f"{name} could not log in: {response and response.status_code}")
        self.http.headers["X-CSRFToken"] = _csrf(self.call("GET", "/", "GET /"))

    def close(self) -> None:
        self.http.close()


def _csrf(page: httpx.Response | None) -> str:
    match = _CSRF.search(page.text) if page is not None else None
    if match is None:
        raise RuntimeError("the page carries no CSRF token")
    return match[1] or match[2]


def _ok(response: httpx.Response | None) -> bool:
    return response is not None and response.is_success


def annotate(client: Client, rng: random.Random) -> None:
    """Take frames from the annotation queue until the deadline: click, save drafts, submit some."""
    while client.working():
        response = client.call("POST", "/api/v1/queue/annotate/next", "POST /api/v1/queue/annotate/next")
        if _ok(response):
            _annotate_frame(client, rng, response.json()["frame_id"])
        elif response is not None and response.status_code == 404:
            time.sleep(0.05)  # nothing approved is waiting: the curators will approve more


def _annotate_frame(client: Client, rng: random.Random, frame_id: int) -> None:
    detail = client.call("GET", f"/api/v1/frames/{frame_id}", "GET /api/v1/frames/{id}")
    if not _ok(detail):
        return
    frame = detail.json()
    version, points = frame["annotation_version"], []
    submits = [False] * rng.randint(1, 2) + ([True] if rng.random() < SUBMIT_SHARE else [])
    for submit in submits:
        for _ in range(rng.randint(1, 3)):
            points.append([rng.uniform(0.1, 0.9) * frame["width"], rng.uniform(0.1, 0.9) * frame["height"]])
        seg = client.call("POST", f"/api/v1/frames/{frame_id}/segment", "POST /api/v1/frames/{id}/segment",
                          json={"points": points, "labels": [1] * len(points), "region_kind": "illusion"})
        if not _ok(seg):
            break
        body = {"version": version, "submit": submit, "illusion_type": "picture",
                "regions": [{"pair": 0, "kind": "illusion", "mask": seg.json()["mask"],
                             "clicks": [{"x": x, "y": y, "label": 1} for x, y in points]}]}
        if not _save(client, frame_id, body):
            break  # 409: a curator sent the frame back meanwhile, or it is someone else's now
        version = client.tally.saves[-1].version
        if rng.random() < STALE_SHARE and _save(client, frame_id, body):
            client.tally.stale_accepted += 1
        if submit:
            return
    client.call("POST", f"/api/v1/frames/{frame_id}/lease/release", "POST /api/v1/frames/{id}/lease/release")


def _save(client: Client, frame_id: int, body: dict[str, Any]) -> bool:
    response = client.call("POST", f"/api/v1/frames/{frame_id}/annotation", "POST /api/v1/frames/{id}/annotation",
                           json=body)
    if not _ok(response):
        return False
    masks = tuple(region["mask"]["counts"] for region in body["regions"])
    client.tally.saves.append(Save(frame_id, body["version"], response.json()["annotation_version"], masks,
                                   body["submit"]))
    return True


def curate(client: Client, rng: random.Random) -> None:
    """Work the review grid until the deadline: a few decisions per page, on pages anywhere in the list."""
    offset = 0
    while client.working():
        page = client.call("GET", f"/api/v1/review/frames?state=all&limit={PAGE}&offset={offset}",
                           "GET /api/v1/review/frames")
        if not _ok(page):
            continue
        listing = page.json()
        offset = rng.randrange(max(1, listing["total"] - PAGE + 1))
        for item in rng.sample(listing["items"], min(DECISIONS_PER_PAGE, len(listing["items"]))):
            decision = _decision(rng, item["state"])
            if decision is None:
                continue
            body = {"decision": decision, "reason": "blurry" if decision == "reject" else "",
                    "revision": item["revision"]}
            response = client.call("POST", f"/api/v1/frames/{item['id']}/review", "POST /api/v1/frames/{id}/review",
                                   json=body)
            if _ok(response):
                client.tally.reviews.append(Decision(item["id"], decision, item["revision"], response.json()["revision"]))


def _decision(rng: random.Random, state: str) -> str | None:
    """Mostly approvals, so the annotators have work; rejected frames come back, approved ones rarely."""
    if state == "prefiltered":
        return "approve" if rng.random() < 0.75 else "reject"
    if state == "rejected":
        return "reset"
    return "reset" if rng.random() < 0.1 else None
