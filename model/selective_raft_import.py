"""Selective-RAFT's published checkpoints (Windsrain/Selective-Stereo, folder Selective-RAFT, MIT:
DataParallel state dicts, keys under ``module.``) as checkpoints of the ``selective-raft`` network:
read weights-only, the architecture inferred from the tensors, every key mapped.

Its encoders are RAFT-Stereo's (``fnet`` BasicEncoder, instance norm; ``cnet`` MultiBasicEncoder,
batch norm, always built with three levels of 128) and map as RAFT-Stereo's do
(:func:`model.raft_import.encoder_prefixes`); its own are the selective GRUs ``gru04/08/16`` (finest
first, whatever n_downsample), the channel and spatial attentions ``cam``/``sam`` and the 1-channel
``disp_head``. What the tensors fix: ``n_downsample`` (the mask head's 9·f² rows), the GRU levels (one
``gru*`` per level), their width, the feature width, the context norm (running statistics: batch,
the only norm its code builds) and the correlation planes (levels × (2·radius + 1)). What they do not
fix — how the planes split into levels and radius — is the demo's default (4 × 4) for the published
layout (:data:`PUBLISHED`) and otherwise comes from ``--corr-levels``/``--corr-radius``: a file of
another layout is refused, naming them, never imported on a guess. Its iterations are the demo's 32
unless ``--iters`` is given. Its code fixes the context norm and never reads ``slow_fast_gru``, so
those flags are refused.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from model.presets import load_preset
from model.raft_import import (
    Conversion,
    Flags,
    NotImportable,
    encoder_prefixes,
    load_mapped,
    mask_factor,
    require,
    tensors_only,
)
from model.raft_import import to_theirs as _mapped_back

SOURCE = "selective-raft"
# The layout of the published files (train_stereo.py's and demo_imgs.py's defaults, which its README's
# fine-tuning commands keep): (n_downsample, GRU levels, hidden, correlation planes) → a description.
PUBLISHED = {(2, 3, 128, 36): "the published layout: train_stereo.py's and demo_imgs.py's defaults"}
CORR_LEVELS, CORR_RADIUS = 4, 4  # demo_imgs.py's defaults: the published files' 36 planes
DEMO_ITERATIONS = 32  # demo_imgs.py's --valid_iters
FLAGS = ("corr_levels", "corr_radius", "iterations")  # the Flags fields a Selective-RAFT file may need
_GRUS = ("04", "08", "16")  # its GRUs by name, finest first


class NotSelectiveRaft(NotImportable):
    """A file that is none of Selective-RAFT's checkpoints (the message says what is missing or wrong)."""


def _prefixes() -> list[tuple[str, str]]:
    """(Selective-RAFT's key prefix, this network's), longest first."""
    pairs = encoder_prefixes() + [("update_block.disp_head.conv1.", "update.disp_head.0."),
                                  ("update_block.disp_head.conv2.", "update.disp_head.2."),
                                  ("sam.samconv.", "sam.conv."), ("cam.fc.", "cam.fc.")]
    for level, name in enumerate(_GRUS):
        pairs += [(f"update_block.gru{name}.{size}_gru.", f"update.grus.{level}.{size}.") for size in ("small", "large")]
    return sorted(pairs, key=lambda pair: -len(pair[0]))


_PREFIXES = _prefixes()


def infer_architecture(state: Mapping[str, Any], flags: Flags = Flags()) -> dict[str, Any]:
    """The ``selective-raft`` network's options for a Selective-RAFT state dict (``module.`` stripped):
    ``{"n_downsample", "gru_levels", "hidden", "feature_dim", "context_norm", "corr_levels",
    "corr_radius", "iterations", "published", "given"}`` (module doc). NotSelectiveRaft naming what is
    missing, what contradicts the tensors, or the flags to give."""
    refused = [f"--{name.replace('_', '-')}" for name, value in vars(flags).items()
               if value is not None and name not in FLAGS]
    if refused:
        raise NotSelectiveRaft(f"{', '.join(refused)}: not an option of Selective-RAFT (its code fixes it or never reads it)")
    required = ["update_block.mask.2.weight", "update_block.gru04.small_gru.convz.weight", "sam.samconv.weight",
                "cam.fc.0.weight", "cnet.conv1.weight", "fnet.conv2.weight", "update_block.encoder.convc1.weight"]
    require(state, required, NotSelectiveRaft, "Selective-RAFT")
    factor = mask_factor(state, NotSelectiveRaft, ", the ones this network has")
    present = [name for name in _GRUS if f"update_block.gru{name}.small_gru.convz.weight" in state]
    levels = len(present)
    if present != list(_GRUS[:levels]):
        raise NotSelectiveRaft(f"GRUs {', '.join('gru' + p for p in present)}: not the finest levels first")
    if levels < 2:  # its update block runs gru04 only `if n_gru_layers > 1`
        raise NotSelectiveRaft("one GRU level: Selective-RAFT's update block never runs its GRU at that setting")
    hidden = state["update_block.gru04.small_gru.convz.weight"].shape[0]
    if "cnet.norm1.running_mean" not in state:
        raise NotSelectiveRaft("its context encoder has no batch-norm statistics: Selective-RAFT builds it with "
                               "batch norm only")
    planes = state["update_block.encoder.convc1.weight"].shape[1]
    n_downsample = 2 if factor == 4 else 3
    published = PUBLISHED.get((n_downsample, levels, hidden, planes))
    if flags.corr_levels is not None and flags.corr_radius is not None \
            and flags.corr_levels * (2 * flags.corr_radius + 1) != planes:
        raise NotSelectiveRaft(f"--corr-levels {flags.corr_levels} × (2·--corr-radius {flags.corr_radius} + 1) is "
                               f"not the {planes} correlation planes the file's motion encoder reads")
    if flags.corr_levels is not None and flags.corr_radius is not None:
        corr = (flags.corr_levels, flags.corr_radius)
    elif published:
        corr = (CORR_LEVELS, CORR_RADIUS)
    else:
        raise NotSelectiveRaft("the tensors do not show Selective-RAFT's published layout, and do not settle how its "
                               f"{planes} correlation planes split: give --corr-levels and --corr-radius "
                               "(levels × (2·radius + 1))")
    given = sorted(name for name, value in vars(flags).items() if value is not None)
    return {"n_downsample": n_downsample, "gru_levels": levels, "hidden": hidden,
            "feature_dim": state["fnet.conv2.weight"].shape[0], "context_norm": "batch",
            "corr_levels": corr[0], "corr_radius": corr[1], "iterations": flags.iterations or DEMO_ITERATIONS,
            "published": published, "given": given}


def convert(state: Mapping[str, Any], flags: Flags = Flags()) -> Conversion:
    """A Selective-RAFT state dict (as loaded; ``module.`` optional) → the ``selective-raft`` network's
    config (its test iterations the demo's, or ``flags.iterations``) and state. NotSelectiveRaft naming
    what is missing, unknown or of the wrong shape, or the flags to give."""
    state = tensors_only(state, NotSelectiveRaft)
    arch = infer_architecture(state, flags)
    config = load_preset(SOURCE, {
        "n_downsample": arch["n_downsample"], "gru_levels": arch["gru_levels"], "hidden_dims": [arch["hidden"]] * 3,
        "feature_dim": arch["feature_dim"], "corr_levels": arch["corr_levels"], "corr_radius": arch["corr_radius"],
        "test_iters": arch["iterations"]})
    network, duplicates, unused = load_mapped(state, config, _PREFIXES, arch["gru_levels"], NotSelectiveRaft,
                                              "Selective-RAFT")
    return Conversion(config, network, arch, len(state), duplicates, unused)


def to_theirs(key: str) -> str:
    """The Selective-RAFT key for this network's key (under the branch): what a file lacks, in its terms."""
    return _mapped_back(key, _PREFIXES)
