"""Selective-IGEV's published checkpoints (Windsrain/Selective-Stereo, MIT: ``sceneflow.pth``, its KITTI,
ETH3D and Middlebury fine-tunes) as checkpoints of the ``selective-igev`` network (its branch,
:class:`~model.stereo.selective_igev.SelectiveIgevBranch`): a DataParallel state dict (keys under
``module.``), read weights-only, the architecture inferred from the tensors where they settle it, every
key placed. The checkpoint importer of ``checkpoints import --from selective-igev`` (model/runs/registry.py
``STEREO_IMPORTERS``: :func:`convert` and :data:`FLAGS`; model.raft_import writes the result).

What the tensors fix: the GRU levels (``update_block.gru16``/``gru08`` present or not), the GRU width (128,
the only one the channel attention allows) and the correlation planes the motion encoder reads
(levels × 9 × (2·radius + 1)). What they do not: ``max_disp`` (the cost volume's span; no tensor depends
on it, and the published files differ — 192 by default, 768 for the Middlebury fine-tune as the README
runs it), so it must be given; the split of the planes into levels and radius, taken as the published
2 × radius 4 when the count is theirs (162) and otherwise to be given. A file that needs a flag is refused,
naming it, never imported on a guess. Iterations: the demo's 32 unless given (the README runs the
Middlebury file with 80).

Tensors with no place of their own: the context encoder's residual blocks hold their shortcut norm twice
(``norm3`` and ``downsample.1``, one module); the training-only upsampling of the initial disparity
(``spx``, ``spx_2``, ``spx_4``) and, with fewer than 3 GRU levels, the context encoder's coarser stages
exist but never run in test mode. A half-precision file is upcast to float32 (the demo runs float32).
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
from model.stereo.selective_igev import DEMO_ITERATIONS, GROUPS, HIDDEN

SOURCE = "selective-igev"
CORR_LEVELS, CORR_RADIUS = 2, 4  # every published file's: 2 × 9 × 9 = 162 planes
_PUBLISHED_PLANES = CORR_LEVELS * (GROUPS + 1) * (2 * CORR_RADIUS + 1)
_MAX_DISP_HINT = "--max-disp 192 (the reference's default: its SceneFlow, KITTI and ETH3D files) or 768 (its " \
                 "middlebury_finetune file, as its README runs it)"
_TRAINING_ONLY = ("spx.", "spx_2.", "spx_4.")


class NotSelectiveIGEV(NotImportable):
    """A file that is not a Selective-IGEV checkpoint, or whose architecture needs flags (the message
    says what is missing, unknown, or which flags to give)."""


@dataclass(frozen=True)
class Flags:
    """What an importer says where the tensors do not: the reference's argparse options ``--max_disp``,
    ``--corr_levels``, ``--corr_radius``, ``--valid_iters``. None: not given."""

    max_disp: int | None = None
    corr_levels: int | None = None
    corr_radius: int | None = None
    iterations: int | None = None


FLAGS = tuple(flag.name for flag in fields(Flags))  # a Selective-IGEV file may need any of them


def _prefixes() -> list[tuple[str, str]]:
    """(the reference's key prefix, ours) where our module is the project's own, longest first."""
    pairs = [("cnet.conv1.", "cnet.trunk.stem.0."), ("cnet.norm1.", "cnet.trunk.stem.1.")]
    pairs += [(f"cnet.layer{stage}.{block}.", f"cnet.trunk.layers.{2 * (stage - 1) + block}.")
              for stage in (1, 2, 3) for block in (0, 1)]
    pairs += [("cnet.layer4.", "cnet.down.0."), ("cnet.layer5.", "cnet.down.1.")]
    for level, resolution in enumerate(("04", "08", "16")):
        pairs += [(f"cnet.outputs{resolution}.{head}.", f"cnet.{('hidden', 'context')[head]}.{level}.")
                  for head in (0, 1)]
    pairs += [(f"update_block.encoder.{theirs}.", f"update_block.encoder.{ours}.") for theirs, ours in
              (("convc1", "corr.0"), ("convc2", "corr.2"), ("convd1", "disp.0"), ("convd2", "disp.2"), ("conv", "out"))]
    return sorted(pairs, key=lambda pair: -len(pair[0]))


_PREFIXES = _prefixes()
_BACK = [(ours, theirs) for theirs, ours in _PREFIXES]  # the same pairs, ours → the reference's, in that order


def _renamed(key: str, prefixes: list[tuple[str, str]], shortcut: tuple[str, str]) -> str:
    """``key`` with the first of ``prefixes`` (old, new) it starts with replaced, and in the context
    encoder its residual blocks' shortcut renamed (``shortcut``: old, new)."""
    for old, new in prefixes:
        if key.startswith(old):
            key = new + key[len(old):]
            break
    return key.replace(*shortcut) if key.startswith("cnet.") else key


def to_ours(key: str) -> str:
    """The reference's key (``module.`` stripped) → this network's."""
    return _renamed(key, _PREFIXES, (".downsample.", ".skip."))


def to_theirs(key: str) -> str:
    """This network's key → the reference's (for messages)."""
    return _renamed(key, _BACK, (".skip.", ".downsample."))


def _never_run(key: str, levels: int) -> bool:
    """A reference key that test mode never reads at ``levels`` GRU levels."""
    if key.startswith(_TRAINING_ONLY):
        return True
    coarse = [("cnet.layer5.", "cnet.outputs16.")] if levels < 3 else []
    coarse += [("cnet.layer4.", "cnet.outputs08.")] if levels < 2 else []
    return any(key.startswith(prefix) for pair in coarse for prefix in pair)


def infer_architecture(state: Mapping[str, Tensor], flags: Flags = Flags()) -> dict[str, Any]:
    """The network's options for a Selective-IGEV state dict (``module.`` stripped): ``{"n_gru_layers",
    "corr_levels", "corr_radius", "max_disp", "iterations", "dtype", "given"}``. NotSelectiveIGEV naming
    what is missing or contradicts the tensors, or the flags to give (module doc)."""
    required = ["feature.conv_stem.weight", "update_block.encoder.convc1.weight", "update_block.gru04.small_gru.convz.weight",
                "cam.fc.0.weight", "sam.samconv.weight", "cost_agg.conv1_up.conv.weight", "cnet.conv1.weight"]
    require(state, required, NotSelectiveIGEV, "Selective-IGEV")
    levels = 1 + ("update_block.gru08.small_gru.convz.weight" in state) + ("update_block.gru16.small_gru.convz.weight" in state)
    if levels == 2 and "update_block.gru08.small_gru.convz.weight" not in state:
        raise NotSelectiveIGEV("update_block.gru16 without gru08: not a layout Selective-IGEV builds")
    hidden = state["update_block.gru04.small_gru.convz.weight"].shape[0]
    if hidden != HIDDEN:
        raise NotSelectiveIGEV(f"GRU width {hidden}: Selective-IGEV's channel attention is built for {HIDDEN}")
    planes = state["update_block.encoder.convc1.weight"].shape[1]
    per_level = GROUPS + 1
    given_corr = flags.corr_levels is not None and flags.corr_radius is not None
    if given_corr:
        corr = (int(flags.corr_levels), int(flags.corr_radius))  # type: ignore[arg-type]
        if corr[0] * per_level * (2 * corr[1] + 1) != planes:
            raise NotSelectiveIGEV(f"--corr-levels {corr[0]} × 9 × (2·--corr-radius {corr[1]} + 1) is not the "
                                   f"{planes} planes the file's motion encoder reads")
    elif flags.corr_levels is not None or flags.corr_radius is not None:
        raise NotSelectiveIGEV("give --corr-levels and --corr-radius together")
    else:
        corr = (CORR_LEVELS, CORR_RADIUS) if planes == _PUBLISHED_PLANES else None
    needed = [] if flags.max_disp is not None else [_MAX_DISP_HINT + " (no tensor holds the cost volume's span)"]
    if corr is None:
        needed.append(f"--corr-levels and --corr-radius (levels × 9 × (2·radius + 1) = its {planes} planes; "
                      f"the published files' are 2 and 4)")
    if needed:
        raise NotSelectiveIGEV("the tensors do not settle Selective-IGEV's architecture: give " + "; ".join(needed))
    assert flags.max_disp is not None and corr is not None
    if flags.max_disp <= 0 or flags.max_disp % 32:
        raise NotSelectiveIGEV(f"--max-disp {flags.max_disp}: must be a positive multiple of 32 (the cost volume at "
                               f"1/4 is halved three times)")
    if flags.iterations is not None and flags.iterations < 1:
        raise NotSelectiveIGEV(f"--iters {flags.iterations}: must be at least 1")
    dtypes = sorted({str(t.dtype).removeprefix("torch.") for t in state.values() if t.is_floating_point()})
    given = sorted(name for name, value in vars(flags).items() if value is not None)
    return {"n_gru_layers": levels, "corr_levels": corr[0], "corr_radius": corr[1], "max_disp": flags.max_disp,
            "iterations": flags.iterations or DEMO_ITERATIONS, "dtype": "/".join(dtypes), "given": given}


def config_for(architecture: Mapping[str, Any]) -> Config:
    """The ``selective-igev`` preset at ``architecture`` (as :func:`infer_architecture` reports it): its
    GRU levels, correlation, max_disp and default iterations; float32, as the demo runs."""
    return load_preset(SOURCE, {"gru_levels": architecture["n_gru_layers"], "corr_levels": architecture["corr_levels"],
                                "corr_radius": architecture["corr_radius"], "max_disp": architecture["max_disp"],
                                "test_iters": architecture["iterations"], "amp": False})


def network_for(architecture: Mapping[str, Any]) -> FusionNetwork:
    """A fresh (untrained) ``selective-igev`` network of ``architecture``: what a saved import is
    rebuilt as (``network_for(arch).load_state_dict(saved)``, then ``.eval()``)."""
    return FusionNetwork(config_for(architecture).model)


def convert(state: Mapping[str, Any], flags: Flags = Flags()) -> Conversion:
    """A Selective-IGEV state dict (as loaded; ``module.`` optional) → the ``selective-igev`` network's
    config (its test iterations the demo's 32, or ``flags.iterations``) and the network with every
    tensor from it, float32, eval mode. NotSelectiveIGEV naming what is missing, unknown or of the wrong
    shape, or the flags to give (:func:`infer_architecture`)."""
    state = tensors_only(state, NotSelectiveIGEV)
    arch = infer_architecture(state, flags)
    config = config_for(arch)
    levels = arch["n_gru_layers"]
    network, duplicates, unused = load_keyed(state, config, NotSelectiveIGEV, "Selective-IGEV", to_ours=to_ours,
                                             to_theirs=to_theirs, never_run=lambda key, _: _never_run(key, levels),
                                             equal_duplicates=True)
    return Conversion(config, network, arch, len(state), duplicates, unused)


def read_published(path: Path) -> dict[str, Any]:
    """A published file's state dict, loaded weights-only (a pickle naming code is refused)."""
    from model.checkpoint import read_weights_only

    state = read_weights_only(Path(path), Path(path).name)
    if not isinstance(state, Mapping):
        raise NotSelectiveIGEV(f"{Path(path).name} holds a {type(state).__name__}, not a state dict")
    return dict(state)


def load_selective_igev(path: Path, flags: Flags = Flags()) -> Conversion:
    """The published file at ``path`` as the loaded ``selective-igev`` network in eval mode (:func:`convert`)."""
    return convert(read_published(path), flags)
