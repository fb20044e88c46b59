"""``illusion-studio geometry …``: the geometry core on files (no data dir needed).

Each command prints one JSON line of figures on success; bad input ends with a one-line
``Error: …`` naming the problem and exit status 1.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import click
import numpy as np

from annotation.inpaint import InpainterError
from core.formats import (
    FormatError,
    read_image,
    read_map,
    read_mask,
    read_rgb,
    write_map,
    write_mask,
    write_rgb,
)
from core.geometry import (
    GeometryError,
    InputError,
    RegionMasks,
    depth_to_disparity,
    load_calibration,
    rectify_disparity,
    reproject_depth,
    synthesize_right_view,
)
from dataset.services.inpaint import HOLE_FILLERS, hole_filler
from webapp.cli.state import CliState

_FILE = click.Path(exists=True, dir_okay=False, path_type=Path)
_OUT = click.Path(dir_okay=False, writable=True, path_type=Path)


@click.group("geometry")
def geometry() -> None:
    """Plane rectification, right-view synthesis and depth reprojection on files.

    Disparity and depth maps are read and written as .pfm, .npy or .png (KITTI uint16
    ×256 disparity); images as 8-bit colour files; masks as PNG (written 0/255).
    """


@geometry.command("right-view")
@click.argument("left", type=_FILE)
@click.argument("disparity", type=_FILE)
@click.option("--out", required=True, type=_OUT, help="Right image to write (.png).")
@click.option("--scale", type=float, default=None, help="Disparity scale s; default: searched for --tau.")
@click.option("--tau", type=float, default=0.9, show_default=True, help="Fraction of pixels to keep in view.")
@click.option(
    "--inpaint",
    type=click.Choice(HOLE_FILLERS),
    default=None,
    help="Hole filling; default: the data dir's inpaint_backend, else telea.",
)
@click.option("--lama-model", type=_FILE, default=None, help="LaMa TorchScript file (for --inpaint lama).")
@click.option("--holes", type=_OUT, default=None, help="Also write the hole mask (.png).")
def right_view(
    left: Path,
    disparity: Path,
    out: Path,
    scale: float | None,
    tau: float,
    inpaint: str | None,
    lama_model: Path | None,
    holes: Path | None,
) -> None:
    """Synthesize the right view of LEFT from its DISPARITY (Algorithm 2)."""
    method, model = _inpaint_config(inpaint, lama_model)
    with _reported():
        result = synthesize_right_view(read_rgb(left), read_map(disparity), scale=scale, tau=tau,
                                       inpaint=hole_filler(method, model))
        write_rgb(out, result.image)
        if holes is not None:
            write_mask(holes, result.holes)
    _echo(
        out=str(out),
        scale=result.scale,
        valid_ratio=round(result.valid_ratio, 6),
        hole_fraction=round(float(result.holes.mean()), 6),
        inpaint=method,
    )


@geometry.command("rectify")
@click.argument("disparity", type=_FILE)
@click.option(
    "--pair",
    "pairs",
    nargs=2,
    multiple=True,
    required=True,
    metavar="ILLUSION SUPPORT",
    help="Illusion and support mask images; SUPPORT '-' uses a ring around the illusion. Repeatable.",
)
@click.option("--out", required=True, type=_OUT, help="Rectified disparity to write.")
@click.option("--image", type=_FILE, default=None, help="Left image to guide the boundary smoothing.")
@click.option("--threshold", type=float, default=0.01, show_default=True, help="RANSAC threshold (normalised d).")
@click.option("--hypotheses", type=int, default=1000, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--qa", type=_OUT, default=None, help="Also write the per-pair QA as JSON.")
@click.option("--strict", is_flag=True, help="Fail on the first skipped or unreliable pair.")
def rectify(
    disparity: Path,
    pairs: tuple[tuple[str, str], ...],
    out: Path,
    image: Path | None,
    threshold: float,
    hypotheses: int,
    seed: int,
    qa: Path | None,
    strict: bool,
) -> None:
    """Replace illusion regions of DISPARITY by the planes of their supports."""
    with _reported():
        regions = [RegionMasks(read_mask(ill), None if sup == "-" else read_mask(sup)) for ill, sup in pairs]
        result = rectify_disparity(
            read_map(disparity),
            regions,
            guide=None if image is None else read_rgb(image),
            threshold=threshold,
            hypotheses=hypotheses,
            seed=seed,
            strict=strict,
        )
        write_map(out, result.disparity)
    figures = {"out": str(out), "rectified": result.rectified_count, "pairs": [r.as_dict() for r in result.reports]}
    if qa is not None:
        qa.write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
    _echo(**figures)


@geometry.command("reproject")
@click.argument("depth", type=_FILE)
@click.option("--calib", required=True, type=_FILE, help="Rig calibration JSON (see core.geometry.calibration).")
@click.option("--out", required=True, type=_OUT, help="Depth in metres to write (.pfm or .npy).")
@click.option("--image", type=_FILE, default=None, help="Colour image guiding the hole filter.")
@click.option("--disparity", "disparity_out", type=_OUT, default=None, help="Also write disparity B·f/Z.")
@click.option("--epsilon", type=float, default=0.05, show_default=True, help="Consistency threshold (m).")
@click.option("--upsample", type=int, default=3, show_default=True)
def reproject(
    depth: Path,
    calib: Path,
    out: Path,
    image: Path | None,
    disparity_out: Path | None,
    epsilon: float,
    upsample: int,
) -> None:
    """Reproject a depth sensor's raw DEPTH (16-bit PNG, .npy or .pfm) into the colour camera."""
    if out.suffix.lower() not in (".pfm", ".npy"):
        raise click.BadParameter("depth in metres is written as .pfm or .npy", param_hint="--out")
    with _reported():
        rig = load_calibration(calib)
        raw = read_image(depth) if depth.suffix.lower() == ".png" else read_map(depth)
        if raw.shape != rig.depth_shape:
            raise InputError(
                f"{depth} has shape {raw.shape} but {calib} gives the depth camera as {rig.depth_shape} (HxW)"
            )
        result = reproject_depth(
            raw,
            rig.K_depth,
            rig.depth_scale,
            rig.R,
            rig.T,
            rig.K_color,
            rig.color_shape,
            guide=None if image is None else read_rgb(image),
            upsample=upsample,
            epsilon=epsilon,
        )
        write_map(out, result)
        if disparity_out is not None:
            write_map(disparity_out, depth_to_disparity(result, rig.baseline, rig.focal))
    _echo(out=str(out), valid_fraction=round(float(np.count_nonzero(result) / result.size), 6))


def _inpaint_config(method: str | None, lama_model: Path | None) -> tuple[str, Path | None]:
    """The inpainting method and LaMa path: options first, then the settings of a data dir
    given to the main group (none when the group runs on its own)."""
    state = click.get_current_context().find_object(CliState)
    if state is not None and state.data_dir is not None:
        settings = state.settings
        method = method or settings.inpaint_backend
        lama_model = lama_model or settings.lama_model_path
    return method or "telea", lama_model


@contextmanager
def _reported() -> Iterator[None]:
    """Bad input becomes a one-line ``Error: …`` (exit 1) instead of a traceback."""
    try:
        yield
    except (GeometryError, InpainterError, FormatError, OSError) as exc:
        raise click.ClickException(str(exc)) from None


def _echo(**figures: object) -> None:
    click.echo(json.dumps(figures))
