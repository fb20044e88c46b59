"""``illusion-studio predict``: run a checkpoint (fusion network or RAFT-Stereo's) on one rectified stereo pair."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from core.formats import FormatError, read_map, read_rgb, write_pfm, write_rgb
from dataset.imported import depth_model_dir
from dataset.preview.images import add_colorbar, colorize, value_range
from model.runs import registry
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state

OUTPUTS = ("confidence", "stereo", "mono_align")
_NO_MODEL = ("no --checkpoint given and this workspace has no current model "
             "(promote a run on the Models page or pass --checkpoint)")
_NO_MONO = ("this model takes the left view's monocular disparity and none is at hand: pass --mono FILE "
            "(.pfm, .npy or the authors' .png), or give the workspace a depth model directory, "
            "depth_backend = \"depth-anything-v2\" and depth_model_path = \"DIR\" (or \"imported:NAME\") in its "
            "illusion-studio.toml")


@click.command("predict")
@click.argument("left", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("right", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--checkpoint", default=None,
              help="RUN:NAME (a run's best, last or checkpoint file, e.g. 3:best), imported:NAME, or a "
                   "checkpoint file's path (default: the workspace's current model).")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="Disparity output (float32 PFM, pixels, left view).")
@click.option("--mono", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Relative mono disparity (.pfm, .npy or the authors' .png); any size. Default: the "
                   "workspace's depth backend estimates it (depth_backend, depth_model_path).")
@click.option("--preview", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write a colour-mapped PNG with a colour bar.")
@click.option("--outputs", default="", help=f"Comma-separated extra maps: {', '.join(OUTPUTS)} (hyphens ok).")
@click.option("--iters", type=click.IntRange(min=1), default=None, help="GRU iterations (default: the config's).")
@click.option("--device", default="cpu", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the confidence flow's noise.")
@pass_state
def predict(state: CliState, left: Path, right: Path, checkpoint: str | None, out: Path, mono: Path | None,
            preview: Path | None, outputs: str, iters: int | None, device: str, seed: int) -> None:
    """Disparity of the LEFT/RIGHT rectified pair (fused, or a stereo-only network's such as an imported
    RAFT-Stereo); extra outputs go beside --out as <stem>_<output>.pfm."""
    extras = [name.strip().replace("-", "_") for name in outputs.split(",") if name.strip()]
    unknown = [name for name in extras if name not in OUTPUTS]
    if unknown:
        raise click.BadParameter(f"unknown output(s) {', '.join(unknown)}; choose from {', '.join(OUTPUTS)}",
                                 param_hint="--outputs")
    if out.suffix.lower() != ".pfm":
        raise click.BadParameter("must end in .pfm", param_hint="--out")
    if checkpoint is None:
        path = registry.current_checkpoint(state.settings)
        if path is None:
            raise click.ClickException(_NO_MODEL)
    else:
        path = _checkpoint_path(state, checkpoint)
    try:
        left_rgb, right_rgb = read_rgb(left), read_rgb(right)
        # a relative disparity: the PNG encoding's scale does not matter, it is affine-invariant
        mono_map = read_map(mono, png="authors") if mono is not None else None
    except FormatError as exc:
        raise click.ClickException(str(exc)) from None
    from model.checkpoint import load_network
    from model.predictor import Predictor

    try:
        network, config, _ = load_network(path, device, label=checkpoint)
        # A stereo-only network (RAFT-Stereo's, or use_mono off) reads no mono disparity.
        if mono_map is None and config.model.use_mono and config.model.mono_backend == "precomputed":
            mono_map = _estimate_mono(state, left_rgb, device)
        result = Predictor(network, config, device).predict(left_rgb, right_rgb, mono_map, iters=iters, seed=seed)
    except ValueError as exc:
        raise click.ClickException(str(exc).splitlines()[0]) from None
    for name in ("disparity", *extras):
        bad = int((~np.isfinite(getattr(result, name))).sum())
        if bad:
            raise click.ClickException(f"the model's {name.replace('_', '-')} is not finite at {bad} of "
                                       f"{result.disparity.size} pixels (a diverged checkpoint?); nothing written")
    out.parent.mkdir(parents=True, exist_ok=True)
    write_pfm(out, result.disparity)
    for name in extras:
        write_pfm(out.with_name(f"{out.stem}_{name}.pfm"), getattr(result, name))
    if preview is not None:
        write_rgb(preview, _preview(result.disparity))
    click.echo(f"wrote {out} ({result.disparity.shape[1]}×{result.disparity.shape[0]}, "
               f"disparity {np.nanmin(result.disparity):.2f}–{np.nanmax(result.disparity):.2f} px)")


def _checkpoint_path(state: CliState, text: str) -> Path:
    """The file ``--checkpoint`` names: a checkpoint name (which needs the workspace) or a path."""
    settings = state.settings if registry.is_name(text) else None
    with service_errors():
        return registry.resolve(settings, text, allow_path=True).path


def _estimate_mono(state: CliState, left: np.ndarray, device: str) -> np.ndarray:
    """The left view's relative disparity (float32 H×W) from the workspace's depth backend; a
    ClickException naming both ways to give one when there is no workspace or no depth model."""
    if state.data_dir is None or state.settings.depth_backend == "precomputed":
        raise click.ClickException(_NO_MONO)
    from annotation.depth import make_depth_backend

    with service_errors():
        model_path = depth_model_dir(state.settings)
    return make_depth_backend(state.settings.depth_backend, model_path=model_path, device=device).estimate(left)


def _preview(disparity: np.ndarray) -> np.ndarray:
    """RGB uint8: the map in the preview colours with a colour bar labelled in pixels."""
    lo, hi = value_range(disparity)
    return add_colorbar(colorize(disparity, lo, hi), lo, hi, unit="px")
