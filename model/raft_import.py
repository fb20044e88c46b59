"""RAFT-Stereo's published checkpoints (princeton-vl/RAFT-Stereo, MIT: ``raftstereo-sceneflow``,
``-middlebury``, ``-eth3d``, ``-realtime``, ``iraftstereo_rvc``) as checkpoints of the ``raft-stereo``
network: read weights-only, the architecture inferred from the tensors, every key mapped.

What the tensors fix: ``n_downsample`` (the mask head's 9·f² rows), the GRU levels (one
``context_zqr_convs`` per level), their width, a shared backbone (no ``fnet``; ``conv2`` on the
context trunk), the context encoder's norm when it has tensors (running statistics: batch; scales
alone: group) and the correlation planes the motion encoder reads (levels × (2·radius + 1)). What they
do not fix — a norm without tensors (instance or none), the slow–fast GRU schedule (a way of running,
not a weight), how the planes split into levels and radius — comes from the flags RAFT-Stereo's README
gives its published files (:data:`PUBLISHED`, with each file's documented iterations) when the tensors
show one of those layouts, and otherwise from the importer's flags (:class:`Flags`): a file of another
layout is refused, naming the flags to give, never imported on a guess. Convex upsampling pads with
zeros, as RAFT-Stereo does.

The encoders' key map (:func:`encoder_prefixes`), the loader (:func:`load_mapped`) and the writer
(:func:`import_file`) serve the networks built on RAFT-Stereo's encoders too
(model/selective_raft_import.py); the loader's core (:func:`load_keyed`, any key map) Selective-IGEV's
(model/selective_igev_import.py).

Two kinds of the file's tensors have no place of their own: RAFT-Stereo's residual blocks hold their
shortcut's norm twice (``norm3`` and ``downsample.1``, one module), and with fewer than 3 GRU levels
its coarsest GRU and context stage exist but never run (``gru32``, ``layer5``, ``outputs32``).
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

from model.network import FusionNetwork
from model.presets import Config, load_preset

SOURCE = "raft-stereo"
PREFIX = "stereo_branch."  # where the network keeps the RAFT-Stereo branch
# The published files' documented flags, by what their tensors show: (shared backbone, GRU levels,
# n_downsample, the context encoder's norm tensors: "batch" running statistics, "affine" scales
# alone, "none") → (files, context_norm, slow_fast_gru, iterations). The iterations are those RAFT-Stereo's
# README runs each with (--valid_iters; the realtime model's 7), the network's default for them.
PUBLISHED: dict[tuple[bool, int, int, str], tuple[str, str, bool, int]] = {
    (False, 3, 2, "batch"): ("raftstereo-sceneflow, raftstereo-middlebury, raftstereo-eth3d", "batch", False, 32),
    (True, 2, 3, "batch"): ("raftstereo-realtime", "batch", True, 7),
    (False, 3, 2, "none"): ("iraftstereo_rvc", "instance", False, 32),
}
_SETTLED_NORM = {"batch": "batch", "affine": "group"}  # norm tensors that name the norm; none: instance or none
CORR_LEVELS, CORR_RADIUS = 4, 4  # every published file's (the motion encoder's 36 correlation planes)
DEMO_ITERATIONS = 32  # RAFT-Stereo's demo default (--valid_iters): a file of another layout runs with it unless told


@dataclass(frozen=True)
class Flags:
    """What an importer says of a file's architecture where its tensors do not: RAFT-Stereo's argparse
    options (``--context_norm``, ``--slow_fast_gru``, ``--corr_levels``, ``--corr_radius``,
    ``--valid_iters``). None: not given (a published layout's documented value, or a refusal)."""

    context_norm: str | None = None
    slow_fast_gru: bool | None = None
    corr_levels: int | None = None
    corr_radius: int | None = None
    iterations: int | None = None


FLAGS = tuple(field.name for field in fields(Flags))  # a RAFT-Stereo file may need any of them


def encoder_prefixes() -> list[tuple[str, str]]:
    """(key prefix, this network's) for what RAFT-Stereo shares with the networks built on it
    (Selective-RAFT): its BasicEncoder ``fnet``, MultiBasicEncoder ``cnet`` (stages ``layer4``/``5``
    and the heads ``outputs08/16/32`` per GRU level), the motion encoder and the mask head."""
    pairs = [("fnet.conv1.", "features.stem.0."), ("fnet.norm1.", "features.stem.1."), ("fnet.conv2.", "features.out."),
             ("cnet.conv1.", "cnet.trunk.stem.0."), ("cnet.norm1.", "cnet.trunk.stem.1."),
             ("update_block.mask.", "update.mask.net.")]
    for encoder, ours in (("fnet", "features"), ("cnet", "cnet.trunk")):
        pairs += [(f"{encoder}.layer{stage}.{block}.", f"{ours}.layers.{2 * (stage - 1) + block}.")
                  for stage in (1, 2, 3) for block in (0, 1)]
    pairs += [(f"cnet.layer{stage}.", f"cnet.down.{stage - 4}.") for stage in (4, 5)]
    for level, resolution in enumerate(("08", "16", "32")):
        pairs += [(f"cnet.outputs{resolution}.{head}.", f"cnet.{('hidden', 'context')[head]}.{level}.") for head in (0, 1)]
    pairs += [(f"update_block.encoder.{theirs}.", f"update.motion.{ours}.") for theirs, ours in
              (("convc1", "corr.0"), ("convc2", "corr.2"), ("convf1", "disp.0"), ("convf2", "disp.2"), ("conv", "out"))]
    return pairs


def _prefixes() -> list[tuple[str, str]]:
    """(RAFT-Stereo's key prefix, this network's), longest first: module for module the same layout."""
    pairs = encoder_prefixes() + [
        ("conv2.", "match_head."), ("context_zqr_convs.", "zqr."),
        ("update_block.flow_head.conv1.", "update.flow_head.0."), ("update_block.flow_head.conv2.", "update.flow_head.2.")]
    pairs += [(f"update_block.gru{resolution}.", f"update.grus.{level}.")
              for level, resolution in enumerate(("08", "16", "32"))]
    return sorted(pairs, key=lambda pair: -len(pair[0]))


_PREFIXES = _prefixes()
# Per GRU level: its GRU, its context heads and the context stage that leads to it.
_LEVELLED = re.compile(r"update\.grus\.(\d)\.|cnet\.(?:hidden|context)\.(\d)\.|cnet\.down\.(\d)\.")
_DUPLICATE = re.compile(r"\.norm3\.")


def to_ours(key: str, prefixes: list[tuple[str, str]] = _PREFIXES) -> str | None:
    """This network's key (under the branch) for a RAFT-Stereo key (``prefixes``: another network's
    table, longest first), or None for one it has no place for. Inside residual blocks RAFT-Stereo's
    ``downsample`` is the shortcut, ``skip`` here."""
    for theirs, ours in prefixes:
        if key.startswith(theirs):
            return ours + key[len(theirs):].replace("downsample.", "skip.")
    return None


def _never_run(key: str, levels: int) -> bool:
    """Whether this network's ``key`` belongs to a GRU level beyond ``levels``: RAFT-Stereo builds all
    three whatever its n_gru_layers, and never runs the others."""
    match = _LEVELLED.match(key)
    if match is None:
        return False
    gru, head, stage = match.groups()
    return int(gru or head or int(stage) + 1) >= levels


def to_theirs(key: str, prefixes: list[tuple[str, str]] = _PREFIXES) -> str:
    """The RAFT-Stereo key (or ``prefixes``' network's) for this network's key (under the branch): what
    a file lacks, in its terms."""
    for theirs, ours in sorted(prefixes, key=lambda pair: -len(pair[1])):
        if key.startswith(ours):
            return theirs + key[len(ours):].replace("skip.", "downsample.")
    return key


class NotImportable(ValueError):
    """A file that is not a checkpoint of the network it is imported as (the message says why)."""


class NotRaftStereo(NotImportable):
    """A file that is none of RAFT-Stereo's checkpoints (the message says what is missing or unknown)."""


@dataclass(frozen=True)
class Conversion:
    config: Config
    network: FusionNetwork  # the raft-stereo network with every tensor from the file, eval mode
    architecture: dict[str, Any]
    tensors_in_file: int
    duplicates: int  # norm3 tensors, the same module as their block's downsample.1
    unused: list[str]  # the file's keys RAFT-Stereo's own forward never reads at this architecture


def strip_module(state: Mapping[str, Any]) -> dict[str, Any]:
    """Keys without DataParallel's ``module.`` (every published file has it)."""
    return {key.removeprefix("module."): value for key, value in state.items()}


def infer_architecture(state: Mapping[str, Tensor], flags: Flags = Flags()) -> dict[str, Any]:
    """The ``raft-stereo`` network's options for a RAFT-Stereo state dict (``module.`` stripped):
    ``{"n_downsample", "gru_levels", "hidden", "shared_backbone", "context_norm", "slow_fast_gru",
    "corr_levels", "corr_radius", "feature_dim", "iterations", "published", "given"}``, what the tensors
    do not settle taken from ``flags``, else from the published layout the tensors show (module doc).
    NotRaftStereo naming what is missing, what contradicts the tensors, or the flags to give."""
    required = ["update_block.mask.2.weight", "context_zqr_convs.0.weight", "cnet.conv1.weight",
                "update_block.encoder.convc1.weight"]
    require(state, required, NotRaftStereo, "RAFT-Stereo")
    factor = mask_factor(state, NotRaftStereo)
    levels = sum(1 for key in state if re.fullmatch(r"context_zqr_convs\.\d\.weight", key))
    if levels not in (1, 2, 3):
        raise NotRaftStereo(f"{levels} context_zqr_convs: RAFT-Stereo has 1 to 3 GRU levels")
    hidden = {state[f"context_zqr_convs.{i}.weight"].shape[0] // 3 for i in range(levels)}
    if len(hidden) != 1:
        raise NotRaftStereo(f"GRU levels of different widths ({sorted(hidden)}): not a layout RAFT-Stereo publishes")
    shared = not any(key.startswith("fnet.") for key in state)
    if shared and "conv2.1.weight" not in state:
        raise NotRaftStereo("no fnet and no conv2 (the shared backbone's matching head): not a RAFT-Stereo checkpoint")
    planes = state["update_block.encoder.convc1.weight"].shape[1]
    tensors = ("batch" if "cnet.norm1.running_mean" in state else "affine" if "cnet.norm1.weight" in state
               else "none")
    n_downsample = 2 if factor == 4 else 3
    published = PUBLISHED.get((shared, levels, n_downsample, tensors)) if planes == CORR_LEVELS * (2 * CORR_RADIUS + 1) \
        else None
    norm, slow_fast, corr, iterations = _unsettled(tensors, planes, published, flags)
    feature_dim = state["conv2.1.weight" if shared else "fnet.conv2.weight"].shape[0]
    given = sorted(name for name, value in vars(flags).items() if value is not None)
    return {"n_downsample": n_downsample, "gru_levels": levels, "hidden": hidden.pop(), "shared_backbone": shared,
            "context_norm": norm, "slow_fast_gru": slow_fast, "corr_levels": corr[0], "corr_radius": corr[1],
            "feature_dim": feature_dim, "iterations": iterations, "published": published[0] if published else None,
            "given": given}


def require(state: Mapping[str, Any], required: list[str], error: type[NotImportable], name: str) -> None:
    """``error`` naming the ``required`` keys that ``state`` lacks: not a checkpoint of ``name``."""
    missing = [key for key in required if key not in state]
    if missing:
        raise error(f"not a {name} checkpoint: no {', '.join(missing)} "
                    f"(it has {len(state)} tensors{', e.g. ' + next(iter(state)) if state else ''})")


def mask_factor(state: Mapping[str, Tensor], error: type[NotImportable], note: str = "") -> int:
    """The upsampling factor f (4 or 8: n_downsample 2 or 3) of the mask head's 9·f² rows; ``error``
    (its message ending in ``note``) for another count."""
    rows = state["update_block.mask.2.weight"].shape[0]
    factor = round((rows / 9) ** 0.5)
    if 9 * factor * factor != rows or factor not in (4, 8):
        raise error(f"update_block.mask.2.weight has {rows} rows: not 9·f² for n_downsample 2 (144) or 3 (576){note}")
    return factor


def _unsettled(tensors: str, planes: int, published: tuple[str, str, bool, int] | None,
               flags: Flags) -> tuple[str, bool, tuple[int, int], int]:
    """(context norm, slow-fast, (corr levels, radius), iterations): each from ``flags`` when given (checked
    against what the tensors do settle), else the ``published`` layout's; NotRaftStereo naming every flag
    a file of another layout needs."""
    settled_norm = _SETTLED_NORM.get(tensors)
    if flags.context_norm is not None:
        possible = (settled_norm,) if settled_norm else ("instance", "none")
        if flags.context_norm not in possible:
            raise NotRaftStereo(f"--context-norm {flags.context_norm} does not fit the file: its context encoder "
                                f"{'has ' + tensors + ' norm tensors' if settled_norm else 'has no norm tensors'}, "
                                f"so its norm is {' or '.join(possible)}")
    if flags.corr_levels is not None and flags.corr_radius is not None \
            and flags.corr_levels * (2 * flags.corr_radius + 1) != planes:
        raise NotRaftStereo(f"--corr-levels {flags.corr_levels} × (2·--corr-radius {flags.corr_radius} + 1) is not the "
                            f"{planes} correlation planes the file's motion encoder reads")
    norm = flags.context_norm or settled_norm or (published[1] if published else None)
    slow_fast = flags.slow_fast_gru if flags.slow_fast_gru is not None else (published[2] if published else None)
    corr = ((flags.corr_levels, flags.corr_radius) if flags.corr_levels is not None and flags.corr_radius is not None
            else (CORR_LEVELS, CORR_RADIUS) if published else None)
    needed = ([] if norm else ["--context-norm instance|none (its context encoder has no norm tensors)"]) \
        + ([] if slow_fast is not None else ["--slow-fast or --no-slow-fast (a way of running: no tensor holds it)"]) \
        + ([] if corr else [f"--corr-levels and --corr-radius (levels × (2·radius + 1) = its {planes} planes)"])
    if needed:
        raise NotRaftStereo("the tensors do not show one of RAFT-Stereo's published layouts, and do not settle its "
                            "architecture: give " + "; ".join(needed))
    iterations = flags.iterations or (published[3] if published else DEMO_ITERATIONS)
    return norm, bool(slow_fast), corr, iterations


def tensors_only(state: Mapping[str, Any], error: type[NotImportable] = NotRaftStereo) -> dict[str, Tensor]:
    """``state`` without DataParallel's ``module.``; ``error`` when a value is not a tensor."""
    state = strip_module(state)
    not_tensors = [key for key, value in state.items() if not isinstance(value, torch.Tensor)]
    if not_tensors:
        raise error(f"not a state dict of tensors: {not_tensors[0]} is a {type(state[not_tensors[0]]).__name__}")
    return state


def load_mapped(state: Mapping[str, Tensor], config: Config, prefixes: list[tuple[str, str]], levels: int,
                error: type[NotImportable], name: str) -> tuple[FusionNetwork, int, list[str]]:
    """The network of ``config`` with every tensor of ``state`` (a file's, ``module.`` stripped) in
    its place by ``prefixes`` (the file's key prefix → ours, longest first; ``levels``: GRU levels run).
    Returns (the network in eval mode, ``norm3`` duplicates skipped, keys the file's own code never runs
    at this architecture); ``error`` (naming the network ``name``) for an unknown, missing, misshapen
    or non-finite tensor."""
    return load_keyed(state, config, error, name, to_ours=lambda key: to_ours(key, prefixes),
                      to_theirs=lambda key: to_theirs(key, prefixes),
                      never_run=lambda key, target: target is not None and _never_run(target, levels))


def load_keyed(state: Mapping[str, Tensor], config: Config, error: type[NotImportable], name: str, *,
               to_ours: Callable[[str], str | None], to_theirs: Callable[[str], str],
               never_run: Callable[[str, str | None], bool],
               equal_duplicates: bool = False) -> tuple[FusionNetwork, int, list[str]]:
    """The network of ``config`` with every tensor of ``state`` (a file's, ``module.`` stripped) in its
    place under the stereo branch: ``to_ours`` (the file's key → the branch's, None where it has none),
    ``to_theirs`` (back, for messages), ``never_run`` (the file's key and ours: one its own code never
    runs at this architecture); a ``norm3`` tensor is skipped for its block's ``downsample.1`` (with
    ``equal_duplicates``, ``error`` if the two differ). Returns (the network in eval mode, duplicates
    skipped, the never-run keys); ``error`` (naming the network ``name``) for an unknown, missing,
    misshapen or non-finite tensor."""
    network = FusionNetwork(config.model)
    expected = network.stereo_branch.state_dict()
    mapped: dict[str, Tensor] = {}
    unknown, unused, duplicates = [], [], 0
    for key, tensor in state.items():
        if _DUPLICATE.search(key) and _DUPLICATE.sub(".downsample.1.", key) in state:
            if equal_duplicates and not torch.equal(tensor, state[_DUPLICATE.sub(".downsample.1.", key)]):
                raise error(f"{key} differs from its block's downsample.1 (one module in the reference)")
            duplicates += 1
            continue
        target = to_ours(key)
        if target is not None and target in expected:
            mapped[target] = tensor
        elif never_run(key, target):
            unused.append(key)
        else:
            unknown.append(key)
    missing = [to_theirs(key) for key in expected if key not in mapped]
    if unknown or missing:
        parts = ([f"unknown {_few(unknown)}"] if unknown else []) + ([f"missing {_few(missing)}"] if missing else [])
        raise error(f"not the {name} layout its tensors suggest: {'; '.join(parts)}")
    for key, tensor in mapped.items():
        theirs = to_theirs(key)
        if tuple(tensor.shape) != tuple(expected[key].shape):
            raise error(f"{theirs} has shape {tuple(tensor.shape)}, expected {tuple(expected[key].shape)}")
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise error(f"{theirs} holds values that are not finite")
    # Copied into the network's float32 parameters: a half file is upcast.
    network.load_state_dict({PREFIX + key: tensor for key, tensor in mapped.items()}, strict=True)
    return network.eval(), duplicates, unused


def convert(state: Mapping[str, Any], flags: Flags = Flags()) -> Conversion:
    """A RAFT-Stereo state dict (as loaded; ``module.`` optional) → the ``raft-stereo`` network's
    config (its test iterations the architecture's documented ones) and state; ``flags``: what the
    tensors do not settle (:func:`infer_architecture`). NotRaftStereo naming what is missing, unknown or
    of the wrong shape, or the flags to give."""
    state = tensors_only(state)
    arch = infer_architecture(state, flags)
    config = load_preset(SOURCE, {
        "n_downsample": arch["n_downsample"], "gru_levels": arch["gru_levels"],
        "hidden_dims": [arch["hidden"]] * 3, "shared_backbone": arch["shared_backbone"],
        "context_norm": arch["context_norm"], "slow_fast_gru": arch["slow_fast_gru"], "feature_dim": arch["feature_dim"],
        "corr_levels": arch["corr_levels"], "corr_radius": arch["corr_radius"], "upsample_border": "zeros",
        "amp": False, "test_iters": arch["iterations"]})  # as its demo: float32
    network, duplicates, unused = load_mapped(state, config, _PREFIXES, arch["gru_levels"], NotRaftStereo,
                                              "RAFT-Stereo")
    return Conversion(config, network, arch, len(state), duplicates, unused)


def _few(keys: list[str]) -> str:
    shown = ", ".join(keys[:3])
    return shown + (f" and {len(keys) - 3} more" if len(keys) > 3 else "")


def read_published(path: Path) -> dict[str, Any]:
    """A published file's state dict, loaded weights-only (a pickle naming code is refused)."""
    from model.checkpoint import read_weights_only

    state = read_weights_only(Path(path), Path(path).name)
    if not isinstance(state, Mapping):
        raise NotImportable(f"{Path(path).name} holds a {type(state).__name__}, not a state dict")
    return dict(state)


def import_file(path: Path, destination: Path, flags: Flags = Flags(), *,
                converter: Callable[[Mapping[str, Any], Flags], Conversion] = convert,
                source: str = SOURCE) -> dict[str, Any]:
    """Convert the published file ``path`` (what its tensors do not settle from ``flags``; ``converter``:
    another network's :func:`convert`, ``source`` its name) and write it, as a checkpoint of this
    project's format, to ``destination`` (atomically). Returns ``{"architecture", "config",
    "keys_loaded", "tensors_in_file", "duplicates", "unused"}``."""
    from model.checkpoint import save_checkpoint

    conversion = converter(read_published(path), flags)
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    meta = {"from": source, "file": Path(path).name, "sha256": digest, "architecture": conversion.architecture,
            "imported_at": datetime.now(UTC).isoformat(timespec="seconds")}
    save_checkpoint(destination, conversion.network, conversion.config, step=0, source=meta)
    return {"architecture": conversion.architecture, "config": conversion.config,
            "keys_loaded": len(conversion.network.state_dict()),
            "tensors_in_file": conversion.tensors_in_file, "duplicates": conversion.duplicates,
            "unused": conversion.unused}


# --- the raft-stereo network's weights → the fusion network's stereo branch (init_stereo) ---------

_MOTION_IN = 64  # RAFT-Stereo's motion encoder width (convc2, convf2 outputs)
_MOTION_OUT = 126  # its motion features; then flow x, flow y


def _stereo_key(key: str) -> str | None:
    """The fusion network's key for a raft-stereo network key; None where the fusion network has no
    counterpart (RAFT-Stereo's image context encoder ``cnet``: the fusion network's context comes from
    the mono branch)."""
    if not key.startswith(PREFIX) or key.startswith(f"{PREFIX}cnet."):
        return None
    rest = key[len(PREFIX):]
    rest = re.sub(r"^zqr\.", "context.zqr.", rest)
    rest = re.sub(r"^update\.grus\.(\d+)\.", r"update.gru\1.", rest)
    rest = re.sub(r"^update\.flow_head\.", "update.disp_head.", rest)
    return PREFIX + rest


def _padded(source: Tensor, shape: torch.Size, cols: list[tuple[slice, slice]] | None = None) -> Tensor:
    """A zero tensor of ``shape`` with ``source`` in its first rows (and, for a weight, its input
    columns moved: (source columns, target columns) pairs): zero rows and columns keep the extra
    channels out of every output, so the wider layer computes what the narrower one did."""
    out = torch.zeros(shape, dtype=source.dtype)
    if cols is None:
        out[: source.shape[0]] = source
    for theirs, ours in cols or []:
        out[: source.shape[0], ours] = source[:, theirs]
    return out


def _changed(key: str, tensor: Tensor, shape: torch.Size) -> Tensor | None:
    """``tensor`` (the raft-stereo network's, under the fusion key ``key``) changed to the fusion
    network's layout where DESIGN.md "Facts about RAFT-Stereo's published checkpoints" says how —
    the motion encoder zero-padded with flow x negated into disparity and flow y dropped, ``gru0``'s
    motion columns [126 features | flow x, flow y] moved to [features, 0… | −flow x], the head's row 0
    negated — or as it is when the shapes agree; None when it does not fit (a narrower network)."""
    motion = f"{PREFIX}update.motion."
    try:
        if key in (f"{PREFIX}update.disp_head.2.weight", f"{PREFIX}update.disp_head.2.bias"):
            fitted = -tensor[:1]  # disparity = −flow x
        elif key.startswith(motion) and tensor.dim() == 1:
            fitted = _padded(tensor, shape)
        elif key == f"{motion}disp.0.weight":
            fitted = _padded(-tensor[:, :1], shape)  # flow x = −disparity; flow y is 0 in stereo
        elif key == f"{motion}out.weight":
            half = shape[1] // 2  # ours: [correlation | disparity] features, motion_dim each
            fitted = _padded(tensor, shape, cols=[(slice(0, _MOTION_IN), slice(0, _MOTION_IN)),
                                                  (slice(_MOTION_IN, 2 * _MOTION_IN), slice(half, half + _MOTION_IN))])
        elif key.startswith(motion):
            fitted = _padded(tensor, shape, cols=[(slice(0, tensor.shape[1]), slice(0, tensor.shape[1]))])
        elif re.fullmatch(rf"{re.escape(PREFIX)}update\.gru0\.conv[zrq]\.weight", key):
            hidden, rest = shape[0], tensor.shape[1] - shape[0] - _MOTION_OUT - 2  # rest: the coarser level's state
            disparity = shape[1] - rest - 1  # ours: [hidden | motion features, 0… | disparity | rest]
            fitted = torch.zeros(shape, dtype=tensor.dtype)
            fitted[:, :hidden + _MOTION_OUT] = tensor[:, :hidden + _MOTION_OUT]
            fitted[:, disparity] = -tensor[:, hidden + _MOTION_OUT]
            fitted[:, disparity + 1:] = tensor[:, hidden + _MOTION_OUT + 2:]
        else:
            fitted = tensor
    except (RuntimeError, IndexError):  # a narrower fusion network: the tensor does not fit
        return None
    return fitted if fitted.shape == shape else None


def stereo_branch_state(raft_state: Mapping[str, Tensor], target: Mapping[str, Tensor],
                        ) -> tuple[dict[str, Tensor], list[str]]:
    """The tensors of a ``raft-stereo`` network's state (``raft_state``, an imported checkpoint's)
    that fit the fusion network whose state is ``target``, under its keys and in its layout (see
    :func:`_changed`), and the keys of ``raft_state`` that have no counterpart or do not fit (RAFT-Stereo's
    image context encoder always; more for a narrower network)."""
    fitted: dict[str, Tensor] = {}
    unused: list[str] = []
    for key, tensor in raft_state.items():
        ours = _stereo_key(key)
        changed = _changed(ours, tensor, target[ours].shape) if ours is not None and ours in target else None
        if changed is None:
            unused.append(key)
        else:
            fitted[ours] = changed.to(target[ours].dtype)  # type: ignore[index]
    return fitted, unused
