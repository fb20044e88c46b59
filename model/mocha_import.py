"""MoCha-Stereo's published checkpoint (ZYangChen/MoCha-Stereo: ``mocha-stereo.pth``, its release
MoCha-Stereo-V1) as a checkpoint of the ``mocha-stereo`` network (its branch,
:class:`~model.stereo.mocha_stereo.MochaBranch`): a DataParallel state dict (keys under ``module.``: its
demo loads the file into ``DataParallel(Mocha(args))``), read weights-only, the architecture inferred from
the tensors where they settle it, every key placed. The checkpoint importer of ``checkpoints import --from
mocha-stereo`` (model/runs/registry.py ``STEREO_IMPORTERS``: :func:`convert` and :data:`FLAGS`).

What the tensors fix: three LSTM levels of 128 (the only layout the reference's update block and channel
widths allow: anything else is refused), the EfficientNetV2-L stages (``feature.block0…4``, saved with the
file although frozen in training: nothing is downloaded) and the correlation planes the motion encoder reads
(levels × 9 × (2·radius + 1), the published 162 taken as 2 × radius 4). What they do not: ``max_disp`` (the
cost volume's span; 192 in the demo, evaluate_stereo.py and the README's runs), so it must be given, as for
Selective-IGEV. Iterations: the demo's 32 unless given.

Tensors with no place of their own: the context encoder's ``norm3`` duplicates (as Selective-IGEV's), the
training-only upsampling of the initial disparity (``spx``, ``spx_2``, ``spx_4``) and MCCV's 1/4 volume
(``mccv.sw_4x``, ``mccv.Conv3d_layer_4x``), which the reference computes but nothing reads.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from torch import Tensor

from model.network import FusionNetwork
from model.presets import Config, load_preset
from model.raft_import import Conversion, NotImportable, load_keyed, require, tensors_only
from model.selective_igev_import import to_ours, to_theirs
from model.stereo.mocha_stereo import DEMO_ITERATIONS, GROUPS, HIDDEN, LEVELS

SOURCE = "mocha-stereo"
CORR_LEVELS, CORR_RADIUS = 2, 4  # the published file's: 2 × 9 × 9 = 162 planes
_PUBLISHED_PLANES = CORR_LEVELS * (GROUPS + 1) * (2 * CORR_RADIUS + 1)
_MAX_DISP_HINT = "--max-disp 192 (the reference's default, with which its demo, evaluate_stereo.py and README run " \
                 "mocha-stereo.pth)"
_NEVER_RUN = ("spx.", "spx_2.", "spx_4.", "mccv.sw_4x.", "mccv.Conv3d_layer_4x.")


class NotMochaStereo(NotImportable):
    """A file that is not a MoCha-Stereo checkpoint, or whose architecture needs flags (the message says
    what is missing, unknown, or which flags to give)."""


@dataclass(frozen=True)
class Flags:
    """What an importer says where the tensors do not: the reference's ``--max_disp``, ``--corr_levels``,
    ``--corr_radius``, ``--valid_iters``. None: not given."""

    max_disp: int | None = None
    corr_levels: int | None = None
    corr_radius: int | None = None
    iterations: int | None = None


FLAGS = tuple(flag.name for flag in fields(Flags))


def infer_architecture(state: Mapping[str, Tensor], flags: Flags = Flags()) -> dict[str, Any]:
    """The network's options for a MoCha-Stereo state dict (``module.`` stripped): ``{"n_gru_layers",
    "corr_levels", "corr_radius", "max_disp", "iterations", "dtype", "given"}``. NotMochaStereo naming what
    is missing or contradicts the tensors, or the flags to give (module doc)."""
    required = ["feature.conv_stem.weight", "feature.block4.0.0.conv_pw.weight", "update_block.encoder.convc1.weight",
                "update_block.lstm04.conv_it.weight", "mccv.sw_8x.weight", "REMP.final_conv.weight", "cnet.conv1.weight"]
    require(state, required, NotMochaStereo, "MoCha-Stereo")
    levels = sum(f"context_zqr_convs.{level}.weight" in state for level in range(4))
    if levels != LEVELS:
        raise NotMochaStereo(f"{levels} context_zqr_convs: MoCha-Stereo's update block runs {LEVELS} LSTM levels "
                             f"(its published layout); no other is imported")
    hidden = state["update_block.lstm04.conv_it.weight"].shape[0]
    if hidden != HIDDEN:
        raise NotMochaStereo(f"LSTM width {hidden}: MoCha-Stereo's published layout is {HIDDEN}")
    planes = state["update_block.encoder.convc1.weight"].shape[1]
    per_level = GROUPS + 1
    if flags.corr_levels is not None and flags.corr_radius is not None:
        corr: tuple[int, int] | None = (int(flags.corr_levels), int(flags.corr_radius))
        assert corr is not None
        if corr[0] * per_level * (2 * corr[1] + 1) != planes:
            raise NotMochaStereo(f"--corr-levels {corr[0]} × 9 × (2·--corr-radius {corr[1]} + 1) is not the "
                                 f"{planes} planes the file's motion encoder reads")
    elif flags.corr_levels is not None or flags.corr_radius is not None:
        raise NotMochaStereo("give --corr-levels and --corr-radius together")
    else:
        corr = (CORR_LEVELS, CORR_RADIUS) if planes == _PUBLISHED_PLANES else None
    needed = [] if flags.max_disp is not None else [_MAX_DISP_HINT + " (no tensor holds the cost volume's span)"]
    if corr is None:
        needed.append(f"--corr-levels and --corr-radius (levels × 9 × (2·radius + 1) = its {planes} planes; "
                      f"the published file's are 2 and 4)")
    if needed:
        raise NotMochaStereo("the tensors do not settle MoCha-Stereo's architecture: give " + "; ".join(needed))
    assert flags.max_disp is not None and corr is not None
    if flags.max_disp <= 0 or flags.max_disp % 32:
        raise NotMochaStereo(f"--max-disp {flags.max_disp}: must be a positive multiple of 32 (the cost volume at "
                             f"1/4 is halved three times)")
    if flags.iterations is not None and flags.iterations < 1:
        raise NotMochaStereo(f"--iters {flags.iterations}: must be at least 1")
    dtypes = sorted({str(t.dtype).removeprefix("torch.") for t in state.values() if t.is_floating_point()})
    given = sorted(name for name, value in vars(flags).items() if value is not None)
    return {"n_gru_layers": levels, "corr_levels": corr[0], "corr_radius": corr[1], "max_disp": flags.max_disp,
            "iterations": flags.iterations or DEMO_ITERATIONS, "dtype": "/".join(dtypes), "given": given}


def config_for(architecture: Mapping[str, Any]) -> Config:
    """The ``mocha-stereo`` preset at ``architecture`` (as :func:`infer_architecture` reports it): its
    correlation, max_disp and default iterations; float32, as the demo runs."""
    return load_preset(SOURCE, {"corr_levels": architecture["corr_levels"], "corr_radius": architecture["corr_radius"],
                                "max_disp": architecture["max_disp"], "test_iters": architecture["iterations"],
                                "amp": False})


def network_for(architecture: Mapping[str, Any]) -> FusionNetwork:
    """A fresh (untrained) ``mocha-stereo`` network of ``architecture``: what a saved import is rebuilt as."""
    return FusionNetwork(config_for(architecture).model)


def convert(state: Mapping[str, Any], flags: Flags = Flags()) -> Conversion:
    """A MoCha-Stereo state dict (as loaded; ``module.`` optional) → the ``mocha-stereo`` network's config
    (its test iterations the demo's 32, or ``flags.iterations``) and the network with every tensor from it,
    float32, eval mode. NotMochaStereo naming what is missing, unknown or of the wrong shape, or the flags
    to give (:func:`infer_architecture`)."""
    state = tensors_only(state, NotMochaStereo)
    arch = infer_architecture(state, flags)
    config = config_for(arch)
    network, duplicates, unused = load_keyed(state, config, NotMochaStereo, "MoCha-Stereo", to_ours=to_ours,
                                             to_theirs=to_theirs, never_run=lambda key, _: key.startswith(_NEVER_RUN),
                                             equal_duplicates=True)
    return Conversion(config, network, arch, len(state), duplicates, unused)


def read_published(path: Path) -> dict[str, Any]:
    """A published file's state dict, loaded weights-only (a pickle naming code is refused)."""
    from model.checkpoint import read_weights_only

    state = read_weights_only(Path(path), Path(path).name)
    if not isinstance(state, Mapping):
        raise NotMochaStereo(f"{Path(path).name} holds a {type(state).__name__}, not a state dict")
    return dict(state)
