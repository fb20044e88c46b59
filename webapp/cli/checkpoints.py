"""``illusion-studio checkpoints import``: a published checkpoint into the workspace, as ``imported:NAME``."""

from __future__ import annotations

import json
from pathlib import Path

import click

from model.runs import registry
from webapp.cli.errors import service_errors
from webapp.cli.state import CliState, pass_state


@click.command("import")
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--from", "source", required=True, type=click.Choice(registry.IMPORT_SOURCES),
              help="Whose checkpoint FILE is: raft-stereo (princeton-vl/RAFT-Stereo's published files), "
                   "selective-raft or selective-igev (Windsrain/Selective-Stereo's Selective-RAFT and "
                   "Selective-IGEV files), mocha-stereo (ZYangChen/MoCha-Stereo's mocha-stereo.pth) or "
                   "depth-anything-v2 (DepthAnything/Depth-Anything-V2's depth_anything_v2_vit*.pth).")
@click.option("--name", default=None, help="Register it as imported:NAME (default: FILE's name, no extension).")
@click.option("--replace", is_flag=True, help="Replace an imported checkpoint of that name.")
@click.option("--context-norm", type=click.Choice(["batch", "group", "instance", "none"]), default=None,
              help="RAFT-Stereo's --context_norm, for a file whose context encoder has no norm tensors "
                   "(instance or none) and is not a published layout.")
@click.option("--slow-fast/--no-slow-fast", "slow_fast", default=None,
              help="RAFT-Stereo's --slow_fast_gru (no tensor holds it): needed unless the file is a published layout.")
@click.option("--corr-levels", type=click.IntRange(1, 8), default=None,
              help="--corr_levels (RAFT-Stereo, Selective-RAFT, Selective-IGEV): needed unless the file is a "
                   "published layout.")
@click.option("--corr-radius", type=click.IntRange(1, 16), default=None,
              help="--corr_radius (RAFT-Stereo, Selective-RAFT, Selective-IGEV): needed unless the file is a "
                   "published layout.")
@click.option("--max-disp", type=click.IntRange(32, 4096), default=None,
              help="Selective-IGEV's and MoCha-Stereo's --max_disp, pixels (no tensor holds it; required): 192 "
                   "for Selective-IGEV's SceneFlow, KITTI and ETH3D files and for mocha-stereo.pth, 768 for "
                   "Selective-IGEV's middlebury_finetune.")
@click.option("--iters", type=click.IntRange(1, 256), default=None,
              help="Its default iterations for predict and evaluate (default: the published file's documented "
                   "ones — RAFT-Stereo realtime 7, the others 32 — else the demo's 32).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as one JSON object.")
@pass_state
def import_checkpoint(state: CliState, file: Path, source: str, name: str | None, replace: bool,
                      context_norm: str | None, slow_fast: bool | None, corr_levels: int | None,
                      corr_radius: int | None, max_disp: int | None, iters: int | None, as_json: bool) -> None:
    """Read FILE weights-only (a file that holds code is refused), infer its architecture from its
    tensors, map every key and register it; `predict --checkpoint imported:NAME` then runs it (a Depth
    Anything V2 file: `depth IMAGE --checkpoint imported:NAME`). Nothing is downloaded: each project's
    README says where its files are. A RAFT-Stereo file whose tensors show none of the published layouts
    is refused unless the flags its tensors cannot settle are given (the refusal names them); so is a
    Selective-RAFT file's, whose only unsettled options are the correlation's levels and radius, and a
    Selective-IGEV or MoCha-Stereo file without --max-disp (its cost volume's span, which no tensor holds)."""
    given = {"context_norm": context_norm, "slow_fast_gru": slow_fast, "corr_levels": corr_levels,
             "corr_radius": corr_radius, "max_disp": max_disp, "iterations": iters}
    with service_errors():
        result = registry.import_checkpoint(state.settings, file, source=source, name=name, replace=replace,
                                            flags=given)
    if as_json:
        click.echo(json.dumps(result, indent=2))
        return
    arch = result["architecture"]
    if source == "depth-anything-v2":
        click.echo(f"{result['checkpoint']}: Depth Anything V2 {arch['encoder']} ({arch['embed_dim']} wide, "
                   f"{arch['depth']} blocks, {arch['heads']} heads; neck {arch['neck_hidden_sizes']}, fusion "
                   f"{arch['fusion_hidden_size']}), relative depth, {result['keys_loaded']} tensors loaded "
                   f"({result['tensors_in_file']} in the file)")
        return
    if source == "selective-raft":
        click.echo(f"{result['checkpoint']}: Selective-RAFT ({arch['published'] or 'a layout no published file has'}"
                   f"), n_downsample {arch['n_downsample']}, {arch['gru_levels']} selective GRU levels of "
                   f"{arch['hidden']}, corr {arch['corr_levels']} levels × radius {arch['corr_radius']}, "
                   f"{arch['iterations']} iterations by default, {result['keys_loaded']} tensors loaded "
                   f"({result['tensors_in_file']} in the file: {result['duplicates']} duplicates, "
                   f"{len(result['unused'])} never used by Selective-RAFT at this architecture)")
        return
    if source == "mocha-stereo":
        click.echo(f"{result['checkpoint']}: MoCha-Stereo, {arch['n_gru_layers']} mogrifier-LSTM levels, "
                   f"max_disp {arch['max_disp']} px, corr {arch['corr_levels']} levels × radius {arch['corr_radius']}, "
                   f"{arch['iterations']} iterations by default, {result['keys_loaded']} tensors loaded "
                   f"({result['tensors_in_file']} in the file: {result['duplicates']} duplicates, "
                   f"{len(result['unused'])} never run in test mode)")
        return
    if source == "selective-igev":
        click.echo(f"{result['checkpoint']}: Selective-IGEV, {arch['n_gru_layers']} selective GRU levels, "
                   f"max_disp {arch['max_disp']} px, corr {arch['corr_levels']} levels × radius {arch['corr_radius']}, "
                   f"{arch['iterations']} iterations by default, {result['keys_loaded']} tensors loaded "
                   f"({result['tensors_in_file']} in the file: {result['duplicates']} duplicates, "
                   f"{len(result['unused'])} never run in test mode)")
        return
    click.echo(f"{result['checkpoint']}: RAFT-Stereo ({arch['published'] or 'a layout none of the published files has'}"
               f"), n_downsample {arch['n_downsample']}, {arch['gru_levels']} GRU levels of {arch['hidden']}, "
               f"{arch['context_norm']}-norm context, {'shared backbone, ' if arch['shared_backbone'] else ''}"
               f"{'slow-fast GRU, ' if arch['slow_fast_gru'] else ''}{arch['iterations']} iterations by default, "
               f"{result['keys_loaded']} tensors loaded "
               f"({result['tensors_in_file']} in the file: {result['duplicates']} duplicates, "
               f"{len(result['unused'])} never used by RAFT-Stereo at this architecture)")
    fits = result["fits"]
    click.echo(f"fits: start from it (--init) with preset {', '.join(fits['init']) or 'none'}; "
               f"its stereo branch (--init-stereo) with {', '.join(fits['init_stereo']) or 'none'}")
