"""Training runs: launching one over a pinned dataset version, and mirroring its progress into the database.

A run is a directory ``<home>/runs/<id>/`` (``runs/`` may be an admin's link to shared storage; the
run's own folder is never a link: see ``dataset.contained``) and a :class:`TrainingRun` row. The product writes
``run.json`` (the engine's whole input: config, dataset version, splits) once, atomically; the
engine (``torchrun -m model.train RUN_DIR``) appends events to ``progress.jsonl`` and writes
checkpoints, and the train job feeds those events to :func:`apply_events`. Config resolution
(preset + overrides) is the model's business, so this module receives the resolved config.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sqlalchemy import and_, func, or_, select
from sqlalchemy.orm import Session

from core.atomic import atomic_write_bytes
from core.wording import quoted
from dataset.contained import LinkedFolder, owned_folder
from dataset.export.splits import MIN_FRACTION, parse_split_spec, split_of
from dataset.media import MediaStore
from dataset.readers import READER_FORMATS, open_reader
from dataset.readers.version import pin_dataset_version, split_by_video, version_counts, version_media_keys
from dataset.redact import redacted
from dataset.run_layout import BEST_NAME, CHECKPOINT_DIR, INIT_FILE, RUN_FILE
from dataset.services import audit
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.tables import Frame, IllusionType, JobState, RunState, Sample, SampleState, TrainingMetric, TrainingRun, User, utcnow

SPLITS = ("train", "val", "test")
DEFAULT_SPLIT = "train=0.8,val=0.1,test=0.1"
SAMPLE_KINDS = ("synthesized", "capture")
DATABASE = "database"
_CHUNK = 1000  # ids per IN (…) query: below every database's limit on bound parameters
_CHECKPOINT = re.compile(r"^(?:step_(\d{7,})|best|best_step_(\d{7,}))\.pt$")


@dataclass(frozen=True)
class DataSelection:
    """What a run trains on: accepted samples of the database (filtered), or a dataset folder."""

    video_ids: tuple[int, ...] = ()
    illusion_types: tuple[str, ...] = ()
    kinds: tuple[str, ...] = ()
    qa_ok: bool = False  # only samples without QA flags
    format: str = DATABASE
    root: str | None = None  # the folder, for any format but the database (never shown)
    label: str | None = None  # how answers name that folder: ``root:relative/path``

    def describe(self) -> str:
        if self.format != DATABASE:
            return f"{self.format} folder {self.label or Path(self.root or '').name}"
        parts = [f"videos {', '.join(map(str, self.video_ids))}" if self.video_ids else "",
                 f"illusion types {', '.join(self.illusion_types)}" if self.illusion_types else "",
                 f"kinds {', '.join(self.kinds)}" if self.kinds else "", "without QA flags" if self.qa_ok else ""]
        return "accepted samples" + "".join(f", {p}" for p in parts if p)


@dataclass(frozen=True)
class Launch:
    """How a run is started: processes per node and devices, and where it starts from."""

    nproc: int = 1
    devices: str = "auto"  # auto, cpu, cuda, cuda:0,1 (the GPUs the trainers may see)
    init_checkpoint: str | None = None  # the file (never shown)
    init_label: str | None = None  # how answers name it: "run 3 · best_step_0000250.pt"
    init_stereo: str | None = None  # an imported RAFT-Stereo checkpoint the stereo branch starts from (never shown)
    init_stereo_label: str | None = None  # its name: "imported:raftstereo-sceneflow"
    nnodes: int = 1
    rdzv_endpoint: str | None = None  # host:port of the rendezvous for a multi-node run
    split: dict[str, float] = field(default_factory=dict)
    seed: int = 0
    # What deals the videos into the split: None, ``seed`` (a run's seed changes its split with the rest);
    # a seed of its own keeps one split over runs of different seeds (a benchmark's paired record).
    split_seed: int | None = None


def run_dir(runs_dir: Path, run_id: int) -> Path:
    """The run's folder, ``runs/<id>``, for reading and writing; LinkedFolder (a 404) when it is a
    symbolic link, so nothing reads or writes through one."""
    return owned_folder(runs_dir, str(run_id))


def parse_split(text: str) -> dict[str, float]:
    """``train=0.8,val=0.1,test=0.1`` → fractions; only train/val/test, train and val not 0."""
    fractions = parse_split_spec(text)
    unknown = sorted(set(fractions) - set(SPLITS))
    if unknown:
        raise InvalidInput(f"split {quoted(unknown[0])}: a run splits into {', '.join(SPLITS)} only")
    for needed in ("train", "val"):
        if needed not in fractions:
            raise InvalidInput(f"split: {needed} needs a fraction of at least {MIN_FRACTION} "
                               "(validation picks the checkpoints)")
    return {name: fractions.get(name, 0.0) for name in SPLITS}


def validate_selection(selection: DataSelection) -> None:
    if selection.format == DATABASE:
        if selection.root:
            raise InvalidInput("--data names a folder; give its --format (the database needs no folder)")
        bad = [t for t in selection.illusion_types if t not in IllusionType.__members__]
        if bad:
            raise InvalidInput(f"illusion type {quoted(bad[0])}: expected one of {', '.join(IllusionType)}")
        bad = [k for k in selection.kinds if k not in SAMPLE_KINDS]
        if bad:
            raise InvalidInput(f"kind {quoted(bad[0])}: expected {' or '.join(SAMPLE_KINDS)}")
        return
    if selection.format not in READER_FORMATS:
        raise InvalidInput(f"data format {quoted(selection.format)}: expected {DATABASE} or one of {', '.join(READER_FORMATS)}")
    if not selection.root or not Path(selection.root).is_dir():
        raise InvalidInput(f"data folder {quoted(selection.label or selection.root)} is not a directory")
    if selection.video_ids or selection.illusion_types or selection.kinds or selection.qa_ok:
        raise InvalidInput("video, illusion type, kind and QA filters select from the database, not from a folder")


def validate_launch(launch: Launch) -> None:
    """What the launch schema (``model/runs/schema.py``) does not see: the command line's multi-node
    options and the start file. Processes, devices and seeds passed the schema."""
    if not 1 <= launch.nnodes <= 1024:
        raise InvalidInput(f"nodes must be 1..1024, got {launch.nnodes}")
    if launch.nnodes > 1 and not launch.rdzv_endpoint:
        raise InvalidInput("a multi-node run needs a rendezvous endpoint HOST:PORT that every node reaches")
    if launch.rdzv_endpoint and not re.match(r"^[A-Za-z0-9_.\-\[\]:]+:\d{1,5}$", launch.rdzv_endpoint):
        raise InvalidInput(f"rendezvous endpoint {quoted(launch.rdzv_endpoint)}: expected HOST:PORT")
    if launch.init_checkpoint is not None and not Path(launch.init_checkpoint).is_file():
        raise InvalidInput(f"init checkpoint {launch.init_label or launch.init_checkpoint} is not a file")


def pin_selection(session: Session, media: MediaStore, selection: DataSelection) -> dict[str, Any]:
    """The dataset version a run trains on; a bad or empty selection is refused with the reason."""
    validate_selection(selection)
    if selection.format != DATABASE:
        return _pin_folder(selection)
    version = pin_dataset_version(
        session, media, video_ids=list(selection.video_ids) or None,
        illusion_types=list(selection.illusion_types) or None, kinds=list(selection.kinds) or None,
        qa_flags=[] if selection.qa_ok else None)
    if not version["items"]:
        raise InvalidInput(f"nothing to train on: no {selection.describe()} in the database; "
                           "accept samples on the Samples page or widen the selection")
    return version


def _pin_folder(selection: DataSelection) -> dict[str, Any]:
    """A folder's version: its sample names (a folder's files are the user's to keep unchanged)."""
    root = selection.root or ""
    try:
        reader = open_reader(selection.format, Path(root))
    except InvalidInput as exc:  # the reader names the folder by its path: answers name it by its label
        raise InvalidInput(str(exc).replace(root, selection.label or Path(root).name)) from None
    names = list(reader.names)
    if not names:
        raise InvalidInput(f"nothing to train on: the {selection.describe()} holds no samples")
    digest = hashlib.sha256(json.dumps([selection.format, names]).encode()).hexdigest()
    return {"id": digest, "created_at": utcnow().isoformat() + "Z",
            "filters": {"format": selection.format, "root": selection.label or Path(selection.root or "").name},
            "items": [{"name": n, "video_id": _folder_group(n), "kind": "synthesized", "illusion_types": []}
                      for n in names]}


def smallest_image(session: Session, version: dict[str, Any], selection: DataSelection) -> tuple[int, int] | None:
    """(H, W) pixels of the smallest image in a pinned version: the most a training crop may take.
    A folder's samples are assumed to share its first sample's size (its readers give no sizes
    without reading the images); None when it cannot be read (the trainer will say why)."""
    if _is_folder(version):
        try:
            height, width = open_reader(selection.format, Path(selection.root or ""))[0].disparity.shape
        except (OSError, ValueError, IndexError):
            return None
        return int(height), int(width)
    ids = [item["sample_id"] for item in version["items"]]
    sizes = [_smallest_frame(session, Sample.id.in_(ids[i:i + _CHUNK])) for i in range(0, len(ids), _CHUNK)]
    sizes = [size for size in sizes if size is not None]
    return (min(h for h, _ in sizes), min(w for _, w in sizes)) if sizes else None


def smallest_accepted_image(session: Session) -> tuple[int, int] | None:
    """(H, W) pixels of the smallest accepted sample's frame: what a launch form's crop suggestion fits."""
    return _smallest_frame(session, Sample.state == SampleState.accepted)


def _smallest_frame(session: Session, where: Any) -> tuple[int, int] | None:
    row = session.execute(select(func.min(Frame.height), func.min(Frame.width))
                          .join(Sample, Sample.frame_id == Frame.id).where(where)).one()
    return (int(row[0]), int(row[1])) if row[0] is not None else None


def _is_folder(version: dict[str, Any]) -> bool:
    return "format" in version.get("filters", {})


def _folder_group(name: str) -> str:
    """A folder sample's video: its name without the last part (``video_3/frame_0007`` → ``video_3``)."""
    return name.rpartition("/")[0] or name


def split_version(version: dict[str, Any], fractions: dict[str, float], seed: int) -> dict[str, list[Any]]:
    """Split by video; refuse when train or validation would be empty (too few videos)."""
    if _is_folder(version):
        splits = _split_folder(version, fractions, seed)
    else:
        splits = split_by_video(version, fractions, seed)
    splits = {name: list(splits.get(name, [])) for name in SPLITS}
    videos = len({item["video_id"] for item in version["items"]})
    for needed in ("train", "val"):
        if not splits[needed]:
            raise InvalidInput(f"the selection holds {videos} video(s) and the {needed} split came out empty; "
                               "select samples of more videos (no video, nor copies of one, is in two splits) or change --split")
    return splits


def _split_folder(version: dict[str, Any], fractions: dict[str, float], seed: int) -> dict[str, list[str]]:
    spec = {name: f for name, f in fractions.items() if f > 0}
    out: dict[str, list[str]] = defaultdict(list)
    for item in version["items"]:
        out[split_of(item["video_id"], spec, seed)].append(item["name"])
    return out


def create_run(session: Session, media: MediaStore, runs_dir: Path, *, preset: str, config: dict[str, Any],
               selection: DataSelection, launch: Launch, version: dict[str, Any], user: User | None) -> TrainingRun:
    """Split the pinned dataset ``version`` (:func:`pin_selection`) and write the run directory with
    ``run.json``.

    The row is flushed (it has its id) but not committed; the caller queues the train job in the
    same transaction. ``config`` is the resolved preset (``Config.to_dict()``). The row's ``launch``
    is what answers show: folders and checkpoints by their labels; their paths go to ``run.json``.
    """
    validate_launch(launch)
    splits = split_version(version, launch.split, launch.seed if launch.split_seed is None else launch.split_seed)
    shown = {**asdict(launch), "init_checkpoint": launch.init_label, "init_stereo": launch.init_stereo_label,
             "data": asdict(selection)}
    shown["data"]["root"] = selection.label or (Path(selection.root).name if selection.root else None)
    del shown["init_label"], shown["init_stereo_label"], shown["data"]["label"]
    run = TrainingRun(preset=preset, config=config, dataset_id=version["id"], dataset=version, splits=splits,
                      launch=shown, created_by_id=user.id if user else None)
    session.add(run)
    session.flush()
    write_run_json(run_dir(runs_dir, run.id), run, media.root, data_root=selection.root,
                   init_checkpoint=launch.init_checkpoint, init_stereo=launch.init_stereo)
    if user is not None:
        audit.record(session, user.id, "run.launch", "run", run.id, preset=preset, dataset=version["id"])
    return run


def write_run_json(directory: Path, run: TrainingRun, media_root: Path, *, data_root: str | None,
                   init_checkpoint: str | None, init_stereo: str | None = None) -> None:
    """The engine's input, written once; a retry finds the same file."""
    data = {"format": run.launch["data"]["format"], "root": data_root}
    doc = {"config": run.config, "dataset": run.dataset, "splits": run.splits, "media_root": str(media_root),
           "init_checkpoint": init_checkpoint, "init_stereo": init_stereo, "data": data, "run": run.id,
           "device": engine_device(run.launch.get("devices", "auto"))}
    atomic_write_bytes(directory / RUN_FILE, json.dumps(doc, indent=1).encode())


def engine_device(devices: str) -> str | None:
    """The engine's device from a launch's ``devices``: which GPUs (``cuda:0,1``) is the launcher's
    business (CUDA_VISIBLE_DEVICES); each rank then takes its local GPU."""
    if devices == "auto":
        return None
    return "cuda" if devices.startswith("cuda") else devices


def test_split(runs_dir: Path, run_id: int) -> list[Any]:
    """The held-out test split of a run (its ``run.json``'s sample ids or names); InvalidInput when
    it has none, so an evaluation says why before it starts."""
    path = run_dir(runs_dir, run_id) / RUN_FILE
    if not path.is_file():
        raise InvalidInput(f"run {run_id} has no run.json")
    test = json.loads(path.read_text(encoding="utf-8")).get("splits", {}).get("test") or []
    if not test:
        raise InvalidInput(f"run {run_id} has an empty test split: launch a run with a test share")
    return list(test)


def get_run(session: Session, run_id: int) -> TrainingRun:
    run = session.get(TrainingRun, run_id)
    if run is None:
        raise NotFound(f"no run {run_id}")
    return run


def run_of_job(session: Session, job_id: int) -> int | None:
    """The run whose train job is ``job_id`` (retrying that job means resuming the run)."""
    return session.scalar(select(TrainingRun.id).where(TrainingRun.job_id == job_id))


def effective_state(run: TrainingRun) -> RunState:
    """The run's state, with a lost worker or a crashed job shown: the reaper (or the job's
    failure) marks the job, not the run."""
    if run.state in (RunState.queued, RunState.running) and run.job is not None:
        if run.job.state == JobState.interrupted:
            return RunState.interrupted
        if run.job.state == JobState.failed:
            return RunState.failed
    return run.state


def kind_counts(version: dict[str, Any]) -> dict[str, int]:
    """Samples of each kind (synthesized, capture) in a version."""
    counts = version_counts(version) if version.get("items") else {}
    return {kind: counts.get(kind, 0) for kind in SAMPLE_KINDS}


def checkpoint_files(directory: Path) -> list[dict[str, Any]]:
    """The run's checkpoint files, newest step first, then the best ones: name, step (None for
    ``best.pt``, whose step is the run's ``best_step``), bytes and path (never for answers).
    Symbolic links and files of other names are not the run's checkpoints."""
    folder = directory / CHECKPOINT_DIR
    if folder.is_symlink():  # a planted link could point anywhere (run_dir refuses the run's own folder as one)
        return []
    found = []
    for path in folder.iterdir() if folder.is_dir() else []:
        match = _CHECKPOINT.match(path.name)
        if match is None or path.is_symlink() or not path.is_file():
            continue
        step = match.group(1) or match.group(2)
        found.append({"name": path.name, "step": int(step) if step else None, "bytes": path.stat().st_size,
                      "path": path})
    return sorted(found, key=lambda c: (c["step"] is None, c["name"].startswith("best"), -(c["step"] or 0)))


def run_json(run: TrainingRun, runs_dir: Path, *, current: dict[str, Any] | None = None,
             full: bool = False) -> dict[str, Any]:
    """What the CLI (``--json``) and the API say about a run; ``full`` adds config, version and splits."""
    try:
        directory: Path | None = run_dir(runs_dir, run.id)
    except LinkedFolder:  # the row is still shown, none of the files the link leads to
        directory = None
    last = directory / run.last_checkpoint if directory and run.last_checkpoint else None
    best = directory / CHECKPOINT_DIR / BEST_NAME if directory else None
    # Answers name files inside the run's folder, never by their server path.
    duration = ((run.finished_at or utcnow()) - run.started_at).total_seconds() if run.started_at else None
    state = effective_state(run)
    # The engine's own words (an exception's) or the job's error: either may quote a server path.
    reason = redacted(run.reason or (run.job.error if state != run.state and run.job is not None else None))
    data: dict[str, Any] = {
        "run": run.id, "job": run.job_id, "state": state.value, "preset": run.preset,
        "step": run.step, "steps": run.steps or run.config.get("train", {}).get("steps", 0),
        "progress": (run.step / run.steps) if run.steps else 0.0,
        "checkpoint": last.name if last is not None and last.is_file() else None,
        "best_checkpoint": best.name if best is not None and best.is_file() else None,
        "resumed_from_step": run.resumed_from_step, "world_size": run.world_size,
        "loss": run.loss, "lr": run.lr, "samples_per_s": run.samples_per_s, "eta_s": run.eta_s,
        "best_val_epe": run.best_val_epe, "best_step": run.best_step, "last_val": run.last_val or None,
        "reason": reason, "cancel_requested": run.cancel_requested,
        "dataset": {"id": run.dataset_id, "samples": len(run.dataset.get("items", [])),
                    "kinds": kind_counts(run.dataset), "filters": run.dataset.get("filters", {}),
                    "splits": {name: len(ids) for name, ids in run.splits.items()}},
        "launch": redacted(run.launch), "run_dir": f"runs/{run.id}",
        "current": bool(current and current.get("run") == run.id),
        "created_by": run.created_by.name if run.created_by else None,
        "created_at": _iso(run.created_at), "started_at": _iso(run.started_at),
        "finished_at": _iso(run.finished_at), "duration_s": duration,
    }
    if directory is not None and run.launch.get("init_stereo"):
        data["init"] = init_report(directory, run.launch["init_stereo"])
    if full:
        files = checkpoint_files(directory) if directory is not None else []
        data.update(config=redacted(run.config), version=run.dataset, splits=run.splits,
                    checkpoints=[{k: v for k, v in f.items() if k != "path"} for f in files])
    return data


def init_report(directory: Path, source: str) -> dict[str, Any]:
    """Which tensors of a run's network came from the checkpoint ``source`` (an ``init_stereo``
    start) and which started fresh: counts and key lists from the engine's ``init.json``, or only
    the source while the engine has not started."""
    report: dict[str, Any] = {"source": source}
    try:
        doc = json.loads((directory / INIT_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return report
    for part in ("loaded", "fresh", "unused"):
        keys = [str(k) for k in doc.get(part, [])] if isinstance(doc, dict) else []
        report[part], report[f"{part}_keys"] = len(keys), keys
    return report


def _iso(value: Any) -> str | None:
    return value.isoformat() + "Z" if value is not None else None


def recent_runs(session: Session, limit: int) -> list[tuple[int, int | None]]:
    """(id, best step) of the newest ``limit`` runs: what a form lists, without their dataset versions."""
    return [(row.id, row.best_step) for row in session.execute(
        select(TrainingRun.id, TrainingRun.best_step).order_by(TrainingRun.id.desc()).limit(limit))]


def list_runs(session: Session, run_ids: Sequence[int] | None = None) -> list[TrainingRun]:
    """Runs newest first: all of them, or those of ``run_ids`` (none for an empty list)."""
    query = select(TrainingRun).order_by(TrainingRun.id.desc())
    if run_ids is not None:
        query = query.where(TrainingRun.id.in_(list(run_ids)))
    return list(session.scalars(query))


def metrics_since(session: Session, run_id: int, after_step: int = -1, after_val: int = -1) -> dict[str, list[dict[str, Any]]]:
    """The run's curve points past what a chart has: ``{"step": [training points with step > after_step],
    "val": [validations with step > after_val]}``, by step (a validation lands after its step's point)."""
    get_run(session, run_id)
    out: dict[str, list[dict[str, Any]]] = {"step": [], "val": []}
    rows = session.scalars(select(TrainingMetric).where(
        TrainingMetric.run_id == run_id,
        or_(and_(TrainingMetric.kind == "step", TrainingMetric.step > after_step),
            and_(TrainingMetric.kind == "val", TrainingMetric.step > after_val))).order_by(TrainingMetric.step))
    for row in rows:
        out.setdefault(row.kind, []).append({"step": row.step, **row.values})
    return out


# --- control -----------------------------------------------------------------------------------

def request_cancel(session: Session, run: TrainingRun, user: User | None, *, trainers_alive: bool = False) -> None:
    """Ask the run to stop: a queued run ends now, a running one when its job has stopped the trainers.

    ``trainers_alive``: a process of the run still lives (the caller looked), so even a run whose
    job ended (failed, interrupted) is cancelled; the caller then ends those processes itself.
    """
    state = effective_state(run)
    if state.finished and not trainers_alive:
        raise Conflict(f"run {run.id} is {state.value}; only queued or running runs can be cancelled")
    run.cancel_requested = True
    who = user.name if user else "the command line"
    run.reason = f"cancelled by {who}"
    if run.job is not None and run.job.state == JobState.queued:
        run.job.state, run.job.error, run.job.finished_at = JobState.failed, run.reason, utcnow()
        run.state, run.finished_at = RunState.cancelled, utcnow()
    elif state.finished:  # no job is left to finish the run
        run.state, run.finished_at = RunState.cancelled, utcnow()
    if user is not None:
        audit.record(session, user.id, "run.cancel", "run", run.id)


def prepare_resume(session: Session, run: TrainingRun, user: User | None) -> int:
    """Check that the run can go on from its last checkpoint; returns the job id to retry."""
    state = effective_state(run)
    if state not in (RunState.interrupted, RunState.failed, RunState.cancelled):
        hint = {RunState.diverged: "; it would diverge again: launch a new run (lower --lr) with --init "
                                   "from its last checkpoint"}.get(state, "")
        raise Conflict(f"run {run.id} is {state.value}; only interrupted, failed or cancelled runs resume{hint}")
    if run.job_id is None:
        raise Conflict(f"run {run.id} has lost its job row; launch a new run")
    run.state, run.cancel_requested, run.reason, run.finished_at = RunState.queued, False, None, None
    if user is not None:
        audit.record(session, user.id, "run.resume", "run", run.id, from_step=run.step)
    return run.job_id


def start_attempt(session: Session, run_id: int, job_id: int) -> TrainingRun:
    """The train job begins (or retries): the run is running again, unless it was cancelled meanwhile."""
    run = get_run(session, run_id)
    if run.cancel_requested:
        raise Conflict(f"run {run_id} was {run.reason or 'cancelled'} before it started")
    run.state, run.job_id, run.reason, run.finished_at = RunState.running, job_id, None, None
    run.started_at = run.started_at or utcnow()
    return run


# --- progress ----------------------------------------------------------------------------------

def read_events(path: Path, offset: int) -> tuple[list[dict[str, Any]], int]:
    """The complete JSON lines of ``path`` after byte ``offset``, and the offset after them.

    A line still being written (no newline yet) waits for the next call; a line that is not JSON
    is skipped, so one bad write cannot stall the mirror.
    """
    if not path.is_file():
        return [], offset
    with path.open("rb") as fh:
        fh.seek(offset)
        chunk = fh.read()
    end = chunk.rfind(b"\n") + 1
    events = []
    for line in chunk[:end].splitlines():
        try:
            event = json.loads(line)
        except ValueError:
            continue
        if isinstance(event, dict):
            events.append(event)
    return events, offset + end


def apply_events(session: Session, run: TrainingRun, events: Iterable[dict[str, Any]]) -> dict[str, Any] | None:
    """Mirror engine events into the run row and its metric points; returns the ``end`` event if one came.

    Idempotent: a resumed run repeats the steps after its checkpoint, and their points are overwritten.
    """
    end = None
    for event in events:
        kind = event.get("event")
        step = int(event.get("step") or 0)
        if kind == "start":
            run.steps, run.world_size = int(event.get("steps") or run.steps), event.get("world_size")
            run.resumed_from_step, run.step = event.get("resumed_from_step"), step
        elif kind == "step":
            run.step, run.steps = step, int(event.get("steps") or run.steps)
            run.loss, run.lr = _number(event.get("loss")), _number(event.get("lr"))
            run.samples_per_s, run.eta_s = _number(event.get("samples_per_s")), _number(event.get("eta_s"))
            _put_point(session, run.id, "step", step, {"loss": run.loss, "lr": run.lr,
                                                       "samples_per_s": run.samples_per_s})
        elif kind == "val":
            metrics, images = event.get("metrics") or {}, list(event.get("images") or [])
            _put_point(session, run.id, "val", step, {"metrics": metrics, "images": images})
            run.last_val = {"step": step, "metrics": metrics, "images": images}
            epe = _number((metrics.get("all") or {}).get("epe"))
            if epe is not None and (run.best_val_epe is None or epe < run.best_val_epe):
                run.best_val_epe = epe
        elif kind == "checkpoint":
            if event.get("best"):  # best.pt, a copy of (or beside) the step's file
                run.best_step = step
            elif event.get("path"):
                run.last_checkpoint = str(event["path"])
        elif kind == "end":
            end = event
            run.step = max(run.step, step)
    return end


def _number(value: Any) -> float | None:
    """JSON numbers as floats; NaN/inf (a diverging loss) and non-numbers as None."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if abs(number) != float("inf") and number == number else None


def _put_point(session: Session, run_id: int, kind: str, step: int, values: dict[str, Any]) -> None:
    point = session.scalar(select(TrainingMetric).where(TrainingMetric.run_id == run_id, TrainingMetric.kind == kind,
                                                        TrainingMetric.step == step))
    if point is None:
        session.add(TrainingMetric(run_id=run_id, kind=kind, step=step, values=values))
    else:
        point.values = values


def finish_run(run: TrainingRun, end: dict[str, Any] | None, exit_code: int | None,
               killed: str | None = None) -> RunState:
    """The run's final state from the engine's ``end`` event and the trainers' exit status.

    ``killed``: how a signal ended the trainers ("rank 0 was killed by SIGKILL — out of memory?"),
    the reason when the engine could not say one itself."""
    if end is not None and end.get("state") == "succeeded" and not exit_code:
        state, run.reason = RunState.succeeded, None  # a cancel that came as the last step ended
    elif run.cancel_requested or (end is not None and end.get("state") == "cancelled"):
        state = RunState.cancelled
        stopped = end is not None and end.get("state") == "cancelled" and end.get("step") is not None
        # The engine's checkpoint of that step is what a resume continues from.
        run.reason = (run.reason or "cancelled") + (f" at step {end['step']}" if stopped else "")
    elif end is not None and end.get("state") in ("succeeded", "diverged", "failed"):
        # A succeeded end with a bad exit status: something failed after the engine's last word.
        state = RunState.failed if end["state"] == "succeeded" else RunState(end["state"])
        run.reason = end.get("reason") or killed or f"trainers exited with status {exit_code}"
    else:
        state = RunState.failed
        run.reason = killed or f"trainers exited with status {exit_code} before the end of the run; see the job log"
    run.state, run.finished_at = state, utcnow()
    return state


# --- what runs keep ----------------------------------------------------------------------------

def pinned_media_keys(session: Session) -> set[str]:
    """Every media key a run's dataset version pins: media gc must keep these files."""
    keys: set[str] = set()
    for version in session.scalars(select(TrainingRun.dataset)):
        if version and not _is_folder(version):
            keys |= version_media_keys(version)
    return keys
