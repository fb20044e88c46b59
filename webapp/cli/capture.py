"""`illusion-studio import-capture` and `illusion-studio import-reconstruction`."""

from __future__ import annotations

from pathlib import Path

import click

from dataset.capture import (
    CAPTURE_JOB,
    DEFAULT_DEPTH_RANGE_M,
    DEFAULT_EPSILON_M,
    MATCH_MODES,
    RECONSTRUCTION_JOB,
    capture_params,
    reconstruction_params,
)
from dataset.db import transaction
from webapp.cli.errors import service_errors
from webapp.cli.ingest import wait_for_jobs
from webapp.cli.state import CliState, pass_state


@click.command("import-capture")
@click.argument("folder", type=click.Path(path_type=Path))
@click.option("--calibration", required=True, type=click.Path(path_type=Path),
              help="Rig calibration JSON (depth camera, colour camera, R, T, baseline, depth_scale).")
@click.option("--scene", default=None, help="Name of the video (default: the folder's name).")
@click.option("--depth-range", nargs=2, type=float, default=DEFAULT_DEPTH_RANGE_M, show_default=True,
              metavar="NEAR FAR", help="Valid ground-truth depth in metres (exclusive).")
@click.option("--epsilon", type=float, default=DEFAULT_EPSILON_M, show_default=True,
              help="Backward-reprojection threshold in metres (Algorithm 3).")
@click.option("--fps", type=float, default=None, help="Capture frame rate, for frame times (default: unknown, 0 s).")
@click.option("--wait", is_flag=True, help="Wait for the job, show progress, exit non-zero if it fails.")
@pass_state
def import_capture(state: CliState, folder: Path, calibration: Path, scene: str | None,
                   depth_range: tuple[float, float], epsilon: float, fps: float | None, wait: bool) -> None:
    """Import a stereo + depth-sensor capture FOLDER (left/, right/, depth/, optional mask/ with
    files matched by stem) as a real-capture video whose frames come with ground-truth disparity."""
    rt = state.runtime
    with service_errors(), transaction(rt.sessions) as s:
        params = capture_params(folder, calibration, scene=scene, depth_range=depth_range, epsilon=epsilon, fps=fps)
        job_id = rt.submit(s, CAPTURE_JOB, params, None).id
    click.echo(f"job {job_id}: import capture {params['path']}")
    if wait:
        wait_for_jobs(state, [job_id])


@click.command("import-reconstruction")
@click.argument("video_id", type=int)
@click.argument("folder", type=click.Path(path_type=Path))
@click.option("--match", type=click.Choice(MATCH_MODES), default="index", show_default=True,
              help="index: file names end with the frame index (frame_000012); order: files in name order, one per frame.")
@click.option("--wait", is_flag=True, help="Wait for the job, show progress, exit non-zero if it fails.")
@pass_state
def import_reconstruction(state: CliState, video_id: int, folder: Path, match: str, wait: bool) -> None:
    """Attach an external reconstruction in FOLDER (disparity/*.pfm|npy in pixels, right/*.png
    rendered right views) to the frames of video VIDEO_ID."""
    rt = state.runtime
    with service_errors(), transaction(rt.sessions) as s:
        params = reconstruction_params(s, video_id, folder, match=match)
        job_id = rt.submit(s, RECONSTRUCTION_JOB, params, None).id
    click.echo(f"job {job_id}: import reconstruction {params['path']} into video {video_id}")
    if wait:
        wait_for_jobs(state, [job_id])
