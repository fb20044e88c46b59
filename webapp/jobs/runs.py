"""Launch, cancel, resume and promote training runs: what the CLI and the API both do, once.

The run row and its train job commit together; the job reaches the ``train`` queue after the commit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy.orm import Session

from dataset.db import transaction
from dataset.services import audit, training
from dataset.services import jobs as job_rows
from dataset.services.dataset_roots import folder_label, resolve_folder
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.tables import JobState, TrainingRun, User
from model.presets import Config, ModelConfig
from model.runs import launcher, registry
from model.runs.capacity import check_fit, train_device
from model.runs.handlers import resolve_config
from model.runs.schema import FieldError, RunLaunch, backbone_dirs, checkpoint_text
from model.runs.start_fit import check_init, check_init_stereo, imported_model
from model.train.spec import with_backbones

if TYPE_CHECKING:
    from webapp.runtime import Runtime

@dataclass(frozen=True)
class ShellOptions:
    """What only the command line may add to a launch (its user has a shell): server paths and
    multi-node rendezvous."""

    data_dir: Path | None = None
    data_format: str | None = None
    init_path: Path | None = None
    nnodes: int = 1
    rdzv_endpoint: str | None = None


def launch_request(rt: Runtime, session: Session, request: RunLaunch, user: User | None,
                   shell: ShellOptions | None = None) -> TrainingRun:
    """A validated launch (API, form, command line): names resolved, then :func:`launch`."""
    shell = shell or ShellOptions()
    if request.data is not None:
        try:
            folder = resolve_folder(rt.settings.dataset_roots, request.data.root, request.data.path)
        except InvalidInput as exc:
            raise FieldError("data", str(exc)) from None
        selection = training.DataSelection(format=request.data.format, root=str(folder),
                                           label=folder_label(request.data.root, request.data.path))
    elif shell.data_dir is not None:
        selection = training.DataSelection(format=shell.data_format or "", root=str(shell.data_dir.resolve()),
                                           label=shell.data_dir.name)
    else:
        selection = training.DataSelection(video_ids=tuple(request.video_ids), illusion_types=tuple(request.illusion_types),
                                           kinds=tuple(request.kinds), qa_ok=request.qa_ok)
    shell_init = (str(shell.init_path.resolve()), shell.init_path.name) if shell.init_path else (None, None)
    settings_launch = training.Launch(
        nproc=request.nproc, devices=request.devices, init_checkpoint=shell_init[0], init_label=shell_init[1],
        nnodes=shell.nnodes, rdzv_endpoint=shell.rdzv_endpoint, split=training.parse_split(request.split),
        seed=request.seed)
    init = _start_from(rt, session, checkpoint_text(request.init), field="init") if request.init else None
    if request.init_stereo is not None:
        stereo = _start_from(rt, session, request.init_stereo, field="init_stereo")
        settings_launch = replace(settings_launch, init_stereo=str(stereo.path), init_stereo_label=stereo.name)
    return launch(rt, session, preset=request.preset, overrides=request.overrides(), selection=selection,
                  launch=settings_launch, user=user, init=init)


def launch(rt: Runtime, session: Session, *, preset: str, overrides: dict[str, Any],
           selection: training.DataSelection, launch: training.Launch, user: User | None,
           init: registry.CheckpointFile | registry.ResolvedCheckpoint | None = None) -> TrainingRun:
    """Create the run (its dataset version pinned, checked to fit the data and the machine,
    ``run.json`` written) and queue its job. ``init``, a checkpoint to start from, is pinned (a run's)
    only once the launch has passed every check."""
    config = resolve_config(preset, {**overrides, "train.seed": launch.seed})
    # The run's config names no backbone directory (answers show it); this machine's settings name
    # them for the memory estimate, and each train worker's own for the engine.
    resolved = Config.from_dict(config)
    resolved = with_backbones(resolved, backbone_dirs(resolved, rt.settings))
    # A start the train worker would refuse is refused here, before the run waits in the queue for it.
    if init is not None:
        check_init(_recorded_model(session, init), resolved, init.label if isinstance(init, registry.CheckpointFile)
                   else init.name)
    elif launch.init_checkpoint is not None:
        check_init(imported_model(Path(launch.init_checkpoint)), resolved, launch.init_label or "the checkpoint")
    if launch.init_stereo is not None:
        check_init_stereo(imported_model(Path(launch.init_stereo)), resolved, launch.init_stereo_label or "the file")
    version = training.pin_selection(session, rt.media, selection)
    check_fit(resolved, nproc=launch.nproc, device=train_device(launch.devices, rt.settings),
              memory_gb=rt.settings.train_memory_gb, smallest_image=training.smallest_image(session, version, selection))
    if isinstance(init, registry.ResolvedCheckpoint):  # an imported checkpoint: no run rotates it
        launch = replace(launch, init_checkpoint=str(init.path), init_label=init.name)
    elif init is not None:
        try:
            pinned = registry.pin(init)
        except ValueError as exc:
            raise FieldError("init", str(exc)) from None
        launch = replace(launch, init_checkpoint=str(pinned.path), init_label=pinned.label)
    run = training.create_run(session, rt.media, rt.settings.runs_dir, preset=preset, config=config,
                              selection=selection, launch=launch, version=version, user=user)
    run.job_id = rt.submit(session, "train", {"run_id": run.id}, user).id
    return run


def cancel(rt: Runtime, run_id: int, user: User | None) -> None:
    """Stop the run in whatever state a process of it lives: its job stops the trainers after they
    checkpoint the step they are at; without a live job (it failed, its worker died) the trainers
    are ended here, from the process group ``trainers.json`` records."""
    directory = training.run_dir(rt.settings.runs_dir, run_id)
    alive = bool(launcher.recorded_members(directory))
    with transaction(rt.sessions) as s:
        run = training.get_run(s, run_id)
        training.request_cancel(s, run, _attached(s, user), trainers_alive=alive)
        handled = run.job is not None and run.job.state == JobState.running
    if alive:
        launcher.request_stop(directory)
        if not handled:
            launcher.stop_recorded(directory)


def resume(rt: Runtime, run_id: int, user: User | None) -> None:
    """Queue the run's job again; the engine resumes from the run's newest checkpoint."""
    if launcher.recorded_members(training.run_dir(rt.settings.runs_dir, run_id)):
        raise Conflict(f"run {run_id}'s trainers are still stopping; resume it once they are gone")
    from webapp.jobs.queue import check_reachable, queue_for  # rt.queue has loaded it: no cycle at import

    check_reachable(rt.queue.hueys[queue_for("train")])  # a 503 before the job is marked queued
    with transaction(rt.sessions) as s:
        job_id = training.prepare_resume(s, training.get_run(s, run_id), _attached(s, user))
        job_rows.mark_for_retry(s, job_id)
    rt.queue.enqueue(job_id, "train")


def promote(rt: Runtime, run_id: int, which: str, user: User | None, *, path: Path | None = None) -> dict[str, Any]:
    """Make the run's ``best`` or ``last`` checkpoint, or one of its files by name — or, from the
    command line, the checkpoint file ``path`` — the current model. The file checked is the file
    promoted (``best.pt`` is frozen first); refused when its weights are not finite (a diverged run's)."""
    from model.checkpoint import load_checkpoint, weights_finite

    with transaction(rt.sessions) as s:
        run = training.get_run(s, run_id)
        created = False
        try:
            if path is None:
                target, created = registry.freeze(_checkpoint_of(rt, run, which, field="checkpoint"))
                file, label = target.path, target.label
            else:
                target = file = path
                label = str(path)
            payload = load_checkpoint(file, label=label)
        except ValueError as exc:
            raise FieldError("checkpoint", str(exc)) from None
        if not weights_finite(payload):
            if created:
                file.unlink(missing_ok=True)
            raise FieldError("checkpoint", f"{label} has non-finite weights (the run diverged); promote another one")
        doc = registry.promote(rt.settings, target, run=run.id, step=int(payload["step"]))
        if user is not None:
            audit.record(s, user.id, "run.promote", "run", run.id, checkpoint=doc["file"], step=doc["step"])
    return doc


def _start_from(rt: Runtime, session: Session, name: str, *, field: str,
                ) -> registry.CheckpointFile | registry.ResolvedCheckpoint:
    """The checkpoint a launch body names (:func:`model.runs.registry.resolve`'s names): a run's as its
    file (pinned once the launch passes), an imported one as resolved; a wrong name is that field's error."""
    try:
        found = registry.resolve(rt.settings, name)
        if found.run is None:
            return found
        run = training.get_run(session, found.run)
    except (NotFound, InvalidInput) as exc:
        raise FieldError(field, str(exc)) from None
    return _checkpoint_of(rt, run, name.split(":", 1)[1], field=field)


def _recorded_model(session: Session, init: registry.CheckpointFile | registry.ResolvedCheckpoint) -> ModelConfig | None:
    """The model config a start checkpoint was trained with: its run's (every checkpoint of a run
    records the run's config), or an imported file's recorded one."""
    if isinstance(init, registry.CheckpointFile):
        try:
            return Config.from_dict(training.get_run(session, init.run).config).model
        except (NotFound, KeyError, ValueError, TypeError):  # a run of an older config: the worker checks the file
            return None
    return imported_model(init.path)


def _checkpoint_of(rt: Runtime, run: TrainingRun, which: str, *, field: str) -> registry.CheckpointFile:
    try:
        return registry.run_checkpoint(rt.settings.runs_dir, run.id, which, best_step=run.best_step)
    except NotFound as exc:
        raise FieldError(field, str(exc)) from None


def _attached(session: Session, user: User | None) -> User | None:
    return session.get(User, user.id) if user is not None else None
