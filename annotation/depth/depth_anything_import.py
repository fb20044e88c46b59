"""Depth Anything V2's original checkpoints (DepthAnything/Depth-Anything-V2, ``depth_anything_v2_vits.pth``
… ``_vitg.pth``: plain state dicts of its ``DepthAnythingV2`` model, a DINOv2 encoder ``pretrained.*`` and
a DPT head ``depth_head.*``) as ``transformers`` ``DepthAnythingForDepthEstimation`` directories, which the
depth backend loads like any released ``-hf`` checkpoint.

What the tensors fix: the encoder (embedding width and block count: vits 384×12, vitb 768×12, vitl
1024×24, vitg 1536×40), the neck widths (``projects``), the fusion width (``layer1_rn``), the head width
and the feed-forward kind (SwiGLU for vitg). What they do not fix comes from the encoder's name, as the
original code has it: the attention heads (64 wide each) and the blocks the head reads. A file with
batch-norm fusion blocks or class-token readouts (options the released files do not use and
``transformers`` lacks) is refused, as is any shape that is none of the four encoders.

The original pipeline differs from ``transformers``' image processor in three places, so the
directory records where it came from (:data:`IMPORT_FILE`) and the backend then runs the original's
steps (see ``annotation.depth.depth_anything``): OpenCV bicubic resizing of the float image, DINOv2's
position-embedding interpolation by a scale factor with a 0.1 offset, and a bilinear
``align_corners=True`` resize of the output back to the image.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import torch
from torch import Tensor

SOURCE = "depth-anything-v2"
IMPORT_FILE = "imported_from.json"  # beside config.json: marks a directory converted from an original file
PATCH = 14
IMAGE_SIZE = 518  # the original DINOv2 encoders' position grid: 37×37 patches of 14 px
# (embedding width, blocks) → (encoder, attention heads, blocks the DPT head reads, 0-based), as the
# original code builds them.
ENCODERS: dict[tuple[int, int], tuple[str, int, list[int]]] = {
    (384, 12): ("vits", 6, [2, 5, 8, 11]),
    (768, 12): ("vitb", 12, [2, 5, 8, 11]),
    (1024, 24): ("vitl", 16, [4, 11, 17, 23]),
    (1536, 40): ("vitg", 24, [9, 19, 29, 39]),
}
_BLOCK = re.compile(r"pretrained\.blocks\.(\d+)\.")


class NotDepthAnything(ValueError):
    """A file that is not one of Depth Anything V2's original checkpoints (the message says why)."""


def infer_architecture(state: Mapping[str, Tensor]) -> dict[str, Any]:
    """The architecture of an original state dict: ``{"encoder", "embed_dim", "depth", "heads",
    "out_indices" (1-based, transformers' hidden-state numbering), "neck_hidden_sizes",
    "fusion_hidden_size", "head_hidden_size", "swiglu"}``. NotDepthAnything saying what is missing
    or does not fit."""
    required = ["pretrained.patch_embed.proj.weight", "pretrained.pos_embed", "pretrained.cls_token",
                "depth_head.scratch.layer1_rn.weight", "depth_head.scratch.output_conv2.0.weight"]
    missing = [key for key in required if key not in state]
    if missing:
        raise NotDepthAnything(f"not a Depth Anything V2 checkpoint: no {', '.join(missing)} (it has "
                               f"{len(state)} tensors{', e.g. ' + next(iter(state)) if state else ''})")
    embed_dim = int(state["pretrained.patch_embed.proj.weight"].shape[0])
    patch = tuple(state["pretrained.patch_embed.proj.weight"].shape[2:])
    if patch != (PATCH, PATCH):
        raise NotDepthAnything(f"patches of {patch}: Depth Anything V2's encoders use {PATCH}×{PATCH}")
    depth = len({int(m.group(1)) for key in state if (m := _BLOCK.match(key))})
    if (embed_dim, depth) not in ENCODERS:
        known = ", ".join(f"{name} {width}×{blocks}" for (width, blocks), (name, _, _) in ENCODERS.items())
        raise NotDepthAnything(f"an encoder {embed_dim} wide with {depth} blocks is none of Depth Anything V2's "
                               f"({known}): its attention heads and the blocks its head reads are not settled")
    encoder, heads, taps = ENCODERS[(embed_dim, depth)]
    extras = [key for key in state if key.startswith("depth_head.readout_projects.")
              or re.search(r"\.resConfUnit\d\.bn\d\.", key)]
    if extras:
        raise NotDepthAnything(f"{extras[0]}: class-token readouts or batch-normed fusion blocks, which the "
                               "released files do not use and transformers' Depth Anything lacks")
    positions = int(state["pretrained.pos_embed"].shape[1]) - 1
    if positions != (IMAGE_SIZE // PATCH) ** 2:
        raise NotDepthAnything(f"pretrained.pos_embed holds {positions} patch positions, not the 37×37 of "
                               f"Depth Anything V2's {IMAGE_SIZE} px encoders")
    neck = []
    for i in range(4):
        key = f"depth_head.projects.{i}.weight"
        if key not in state:
            raise NotDepthAnything(f"not a Depth Anything V2 checkpoint: no {key}")
        neck.append(int(state[key].shape[0]))
    return {"encoder": encoder, "embed_dim": embed_dim, "depth": depth, "heads": heads,
            "out_indices": [tap + 1 for tap in taps], "neck_hidden_sizes": neck,
            "fusion_hidden_size": int(state["depth_head.scratch.layer1_rn.weight"].shape[0]),
            "head_hidden_size": int(state["depth_head.scratch.output_conv2.0.weight"].shape[0]),
            "swiglu": "pretrained.blocks.0.mlp.w12.weight" in state}


def to_transformers(state: Mapping[str, Tensor], arch: Mapping[str, Any]) -> tuple[dict[str, Tensor], list[str]]:
    """(the original tensors under ``DepthAnythingForDepthEstimation``'s keys, the fused ``qkv`` and
    SwiGLU ``w12`` matrices split into their parts; the original keys no rule places)."""
    out: dict[str, Tensor] = {}
    unplaced: list[str] = []
    width = arch["embed_dim"]
    stem = {"cls_token": "cls_token", "mask_token": "mask_token", "pos_embed": "position_embeddings",
            "patch_embed.proj.weight": "patch_embeddings.projection.weight",
            "patch_embed.proj.bias": "patch_embeddings.projection.bias"}
    block = {"norm1.": "norm1.", "norm2.": "norm2.", "attn.proj.": "attention.o_proj.", "ls1.gamma": "layer_scale1.lambda1",
             "ls2.gamma": "layer_scale2.lambda1", "mlp.fc1.": "mlp.fc1.", "mlp.fc2.": "mlp.fc2.", "mlp.w3.": "mlp.down_proj."}
    # The original's refinenet4 fuses the coarsest level first; transformers numbers its fusion layers
    # in the order they run.
    head = {"scratch.output_conv1.": "head.conv1.", "scratch.output_conv2.0.": "head.conv2.",
            "scratch.output_conv2.2.": "head.conv3."}
    for i in range(4):
        head[f"projects.{i}."] = f"neck.reassemble_stage.layers.{i}.projection."
        head[f"resize_layers.{i}."] = f"neck.reassemble_stage.layers.{i}.resize."
        head[f"scratch.layer{i + 1}_rn."] = f"neck.convs.{i}."
        fusion = f"neck.fusion_stage.layers.{3 - i}."
        head[f"scratch.refinenet{i + 1}.out_conv."] = fusion + "projection."
        for unit in (1, 2):
            for conv in (1, 2):
                head[f"scratch.refinenet{i + 1}.resConfUnit{unit}.conv{conv}."] = (
                    f"{fusion}residual_layer{unit}.convolution{conv}.")
    for key, tensor in state.items():
        if key.startswith("pretrained."):
            rest = key[len("pretrained."):]
            if rest in stem:
                out[f"backbone.embeddings.{stem[rest]}"] = tensor
            elif rest.startswith("norm."):
                out["backbone.layernorm." + rest[len("norm."):]] = tensor
            elif (match := re.fullmatch(r"blocks\.(\d+)\.(.+)", rest)):
                layer, part = f"backbone.encoder.layer.{match.group(1)}.", match.group(2)
                if part.startswith("attn.qkv."):
                    suffix = part[len("attn.qkv."):]
                    for index, name in enumerate(("q_proj", "k_proj", "v_proj")):
                        out[f"{layer}attention.{name}.{suffix}"] = tensor[index * width:(index + 1) * width]
                elif part.startswith("mlp.w12."):
                    half = tensor.shape[0] // 2  # [gate; up]: the original takes silu(first half) · second half
                    suffix = part[len("mlp.w12."):]
                    out[f"{layer}mlp.gate_proj.{suffix}"] = tensor[:half]
                    out[f"{layer}mlp.up_proj.{suffix}"] = tensor[half:]
                else:
                    prefix = next((p for p in block if part.startswith(p)), None)
                    if prefix is None:
                        unplaced.append(key)
                    else:
                        out[layer + block[prefix] + part[len(prefix):]] = tensor
            else:
                unplaced.append(key)
        elif key.startswith("depth_head."):
            rest = key[len("depth_head."):]
            prefix = next((p for p in head if rest.startswith(p)), None)
            if prefix is None:
                unplaced.append(key)
            else:
                out[head[prefix] + rest[len(prefix):]] = tensor
        else:
            unplaced.append(key)
    return out, unplaced


def build_config(arch: Mapping[str, Any]) -> Any:
    """``DepthAnythingConfig`` for an architecture of :func:`infer_architecture` (relative depth)."""
    from transformers import DepthAnythingConfig, Dinov2Config

    backbone = Dinov2Config(hidden_size=arch["embed_dim"], num_hidden_layers=arch["depth"],
                            num_attention_heads=arch["heads"], mlp_ratio=4, patch_size=PATCH, image_size=IMAGE_SIZE,
                            layerscale_value=1.0, use_swiglu_ffn=arch["swiglu"], out_indices=arch["out_indices"],
                            apply_layernorm=True, reshape_hidden_states=False, layer_norm_eps=1e-6)
    return DepthAnythingConfig(backbone_config=backbone, reassemble_hidden_size=arch["embed_dim"], patch_size=PATCH,
                               neck_hidden_sizes=list(arch["neck_hidden_sizes"]),
                               fusion_hidden_size=arch["fusion_hidden_size"], head_hidden_size=arch["head_hidden_size"],
                               reassemble_factors=[4, 2, 1, 0.5], depth_estimation_type="relative", max_depth=1)


def convert(state: Mapping[str, Any]) -> tuple[Any, dict[str, Any], int]:
    """An original state dict (as loaded; ``module.`` optional) → (``DepthAnythingForDepthEstimation``
    in eval mode holding every tensor, its architecture, the tensors in the file). NotDepthAnything
    naming what is missing, unknown or of the wrong shape."""
    from transformers import DepthAnythingForDepthEstimation

    state = {key.removeprefix("module."): value for key, value in state.items()}
    not_tensors = [key for key, value in state.items() if not isinstance(value, torch.Tensor)]
    if not_tensors:
        raise NotDepthAnything(f"not a state dict of tensors: {not_tensors[0]} is a "
                               f"{type(state[not_tensors[0]]).__name__}")
    arch = infer_architecture(state)
    mapped, unknown = to_transformers(state, arch)
    model = DepthAnythingForDepthEstimation(build_config(arch))
    expected = model.state_dict()
    unknown += sorted(key for key in mapped if key not in expected)
    missing = sorted(key for key in expected if key not in mapped)
    if unknown or missing:
        parts = ([f"unknown {_few(unknown)}"] if unknown else []) + ([f"missing {_few(missing)}"] if missing else [])
        raise NotDepthAnything(f"not the Depth Anything V2 layout its tensors suggest: {'; '.join(parts)}")
    for key, tensor in mapped.items():
        if tuple(tensor.shape) != tuple(expected[key].shape):
            raise NotDepthAnything(f"{key} would have shape {tuple(tensor.shape)}, the {arch['encoder']} model's "
                                   f"is {tuple(expected[key].shape)}")
        if not bool(torch.isfinite(tensor).all()):
            raise NotDepthAnything(f"the file's tensor for {key} holds values that are not finite")
    model.load_state_dict({key: tensor.float() for key, tensor in mapped.items()}, strict=True)
    return model.eval(), arch, len(state)


def _few(keys: list[str]) -> str:
    shown = ", ".join(keys[:3])
    return shown + (f" and {len(keys) - 3} more" if len(keys) > 3 else "")


def read_original(path: Path, read: Callable[[Path, str], Any]) -> dict[str, Any]:
    """An original file's state dict, loaded by ``read(path, label)`` — the model package's weights-only
    loader, passed in since ``annotation`` imports nothing of ``model`` (a pickle naming code is refused)."""
    state = read(Path(path), Path(path).name)
    if not isinstance(state, Mapping):
        raise NotDepthAnything(f"{Path(path).name} holds a {type(state).__name__}, not a state dict")
    return dict(state)


def import_file(path: Path, destination: Path, read: Callable[[Path, str], Any]) -> dict[str, Any]:
    """Convert the original file ``path`` (loaded by ``read``, see :func:`read_original`) and write it to
    the directory ``destination`` (built aside and renamed into place; an existing one is replaced):
    ``config.json``, ``model.safetensors`` and :data:`IMPORT_FILE`. Returns ``{"architecture",
    "keys_loaded", "tensors_in_file"}``."""
    path = Path(path)
    if "metric" in path.name.lower():
        # The metric-depth files have exactly the relative ones' tensors; only their head's last
        # activation (a sigmoid times a maximum depth) differs, and nothing in the file says which.
        raise NotDepthAnything(f"{path.name} looks like a metric-depth file (its name says metric): its tensors "
                               "match the relative models' but its output is not relative disparity; only the "
                               "relative depth_anything_v2_vit*.pth files import")
    model, arch, tensors = convert(read_original(path, read))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    source = {"from": SOURCE, "file": path.name, "sha256": digest, "architecture": arch, "pipeline": "original",
              "imported_at": datetime.now(UTC).isoformat(timespec="seconds")}
    destination = Path(destination)
    destination.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{destination.name}-", dir=destination.parent))
    from transformers.utils import logging as hf_logging

    bars = hf_logging.is_progress_bar_enabled()
    hf_logging.disable_progress_bar()  # its bar on stderr would garble the command's (JSON) answer
    try:
        model.save_pretrained(staging, safe_serialization=True)
        (staging / IMPORT_FILE).write_text(json.dumps(source, indent=1), encoding="utf-8")
        old = destination.with_name(f".{destination.name}-old-{os.getpid()}")
        if destination.exists():
            os.replace(destination, old)
        os.replace(staging, destination)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        if bars:
            hf_logging.enable_progress_bar()
    return {"architecture": arch, "keys_loaded": len(model.state_dict()), "tensors_in_file": tensors}


def imported_source(path: Path) -> dict[str, Any] | None:
    """What :data:`IMPORT_FILE` in the checkpoint directory ``path`` says, or None when it has none (a
    directory saved by ``transformers`` itself)."""
    file = Path(path) / IMPORT_FILE
    if not file.is_file():
        return None
    try:
        doc = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise ValueError(f"{file} is not readable JSON; import the original file again") from None
    return doc if isinstance(doc, dict) else None
