"""``illusion-studio depth``: a monocular depth model's relative disparity of one image."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from core.formats import FormatError, read_rgb, write_pfm
from dataset.imported import depth_model_dir
from model.runs import registry
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state

_NO_MODEL = ("no --checkpoint given and this workspace has no depth model (depth_backend = \"depth-anything-v2\" "
             "and depth_model_path = \"DIR\" or \"imported:NAME\" in its illusion-studio.toml); "
             "pass --checkpoint imported:NAME or DIR")


@click.command("depth")
@click.argument("image", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--checkpoint", default=None,
              help="imported:NAME (an imported Depth Anything V2 file) or a Depth Anything checkpoint "
                   "directory (default: the workspace's depth_model_path).")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="Relative disparity output (float32 PFM, the image's size; larger = nearer).")
@click.option("--device", default="cpu", show_default=True)
@pass_state
def depth(state: CliState, image: Path, checkpoint: str | None, out: Path, device: str) -> None:
    """Relative disparity (inverse depth, up to scale and shift) of IMAGE from a Depth Anything V2
    model; an imported original file runs as the original code's infer_image(image, 518)."""
    if out.suffix.lower() != ".pfm":
        raise click.BadParameter("must end in .pfm", param_hint="--out")
    if checkpoint is None:
        if state.data_dir is None or state.settings.depth_backend != "depth-anything-v2":
            raise click.ClickException(_NO_MODEL)
        with service_errors():  # unset: the backend says it needs one
            path = depth_model_dir(state.settings)
    else:
        settings = state.settings if checkpoint.startswith(f"{registry.IMPORTED}:") else None
        with service_errors():
            path = registry.resolve_depth_model(settings, checkpoint).path
    try:
        rgb = read_rgb(image)
    except FormatError as exc:
        raise click.ClickException(str(exc)) from None
    from annotation.depth import DepthError, make_depth_backend

    try:
        disparity = make_depth_backend("depth-anything-v2", model_path=path, device=device).estimate(rgb)
    except (ValueError, DepthError) as exc:
        raise click.ClickException(str(exc).splitlines()[0]) from None
    bad = int((~np.isfinite(disparity)).sum())
    if bad:
        raise click.ClickException(f"the model's disparity is not finite at {bad} of {disparity.size} pixels; "
                                   "nothing written")
    out.parent.mkdir(parents=True, exist_ok=True)
    write_pfm(out, disparity)
    click.echo(f"wrote {out} ({disparity.shape[1]}×{disparity.shape[0]}, relative disparity "
               f"{float(disparity.min()):.4g}–{float(disparity.max()):.4g})")
