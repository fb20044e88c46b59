"""The methods an evaluation compares, each a disparity predictor over :class:`StereoSample`s.

``fusion``, ``stereo`` and ``mono_align`` share one forward pass of a fusion checkpoint per
sample; ``raft_stereo``, ``selective_raft``, ``selective_igev`` and ``mocha_stereo`` are stereo-only networks'
disparities (RAFT-Stereo's, Selective-RAFT's, Selective-IGEV's, MoCha-Stereo's, e.g. imported published checkpoints:
:data:`BASELINE_METHODS`); each network method may have a checkpoint of its own, and methods that
share one share its forward pass. ``mono_gt_align``
and ``sgbm`` need no network (torch loads only when a network method is asked for); ``predictions``
reads another program's PFMs.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from core.formats import read_pfm
from core.geometry.consistency import sgbm_disparity
from dataset.readers import SampleError, StereoSample
from dataset.readers.base import resize_disparity, resize_image
from model.align import AlignRule, align


class Baseline(NamedTuple):
    """A baseline network's method: the model.architecture its checkpoint must have, the network's
    name, the checkpoint a message gives as an example, and what `checkpoints import --from
    ARCHITECTURE` needs besides the file for its published files (shown where none is imported yet)."""

    architecture: str
    title: str
    example: str
    import_flags: str = ""


# Each scores its own checkpoint's disparity.
BASELINE_METHODS: dict[str, Baseline] = {
    "raft_stereo": Baseline("raft-stereo", "RAFT-Stereo", "imported:raftstereo-sceneflow"),
    "selective_raft": Baseline("selective-raft", "Selective-RAFT", "imported:sceneflow"),
    "selective_igev": Baseline("selective-igev", "Selective-IGEV", "imported:selective-igev-sceneflow",
                               "--max-disp 192"),  # no tensor holds it: 768 for middlebury_finetune
    "mocha_stereo": Baseline("mocha-stereo", "MoCha-Stereo", "imported:mocha-stereo", "--max-disp 192")}
METHODS = ("fusion", "stereo", "mono_align", *BASELINE_METHODS, "mono_gt_align", "sgbm", "predictions")
NETWORK_METHODS = ("fusion", "stereo", "mono_align", *BASELINE_METHODS)
FUSION_METHODS = ("fusion", "stereo", "mono_align")  # read from one fusion checkpoint's forward pass


def method_key(name: str) -> str:
    """CLI spelling (``mono-gt-align``) to the key used in reports (``mono_gt_align``)."""
    key = name.strip().lower().replace("-", "_")
    if key not in METHODS:
        raise ValueError(f"unknown method {name!r}; choose from {', '.join(m.replace('_', '-') for m in METHODS)}")
    return key


def resize_relative(mono: np.ndarray, height: int, width: int) -> np.ndarray:
    """A relative (affine-invariant) disparity at another size: values are kept, not scaled."""
    mono = np.nan_to_num(np.asarray(mono, np.float32))
    return mono if mono.shape == (height, width) else resize_image(mono, (height, width))


def fill_holes(disparity: np.ndarray) -> np.ndarray:
    """Fill NaN pixels of each row with the smaller of the nearest valid disparities to their left
    and right (occlusions belong to the background, as the KITTI devkit's interpolation assumes);
    a row without any valid pixel becomes 0. Dense output, float32 HxW."""
    valid = np.isfinite(disparity)
    h, w = disparity.shape
    cols = np.arange(w)
    left_idx = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)
    right_idx = np.minimum.accumulate(np.where(valid, cols, w)[:, ::-1], axis=1)[:, ::-1]
    padded = np.concatenate([np.where(valid, disparity, np.inf), np.full((h, 1), np.inf)], axis=1)
    rows = np.arange(h)[:, None]
    from_left = np.where(left_idx >= 0, padded[rows, np.maximum(left_idx, 0)], np.inf)
    from_right = np.where(right_idx < w, padded[rows, np.minimum(right_idx, w)], np.inf)
    filled = np.minimum(from_left, from_right)
    return np.where(np.isfinite(filled), filled, 0).astype(np.float32)


def sgbm_max_disparity(width: int) -> int:
    """SGBM's search range from the image width alone (a quarter of it, a multiple of 16): no ground
    truth is ever looked at."""
    return max(16, int(np.ceil(width / 4 / 16)) * 16)


@dataclass(frozen=True)
class SgbmParams:
    """The baseline's parameters, printed in every report."""

    max_disparity: int | None = None  # None: :func:`sgbm_max_disparity` of each image
    block_size: int = 5
    hole_fill: str = "row-wise minimum of the nearest valid neighbours; 0 where a row has none"


class Mono:
    """Where a sample's monocular disparity comes from: the dataset, or ``--mono DIR``
    (``DIR/<sample path>.pfm``, any size; values kept, since they are affine-invariant)."""

    def __init__(self, directory: Path | None) -> None:
        self.directory = directory

    def __call__(self, sample: StereoSample) -> np.ndarray:
        h, w = sample.disparity.shape
        if self.directory is not None:
            path = prediction_path(self.directory, sample)
            if not path.is_file():
                raise SampleError(f"no monocular disparity {path}")
            return resize_relative(read_pfm(path), h, w)
        if sample.mono is None:
            raise SampleError("this dataset carries no monocular disparity: pass --mono DIR")
        return resize_relative(sample.mono, h, w)


def prediction_path(directory: Path, sample: StereoSample) -> Path:
    """``DIR/REL/x.pfm`` for the sample whose left image is ``REL/x.png`` in its dataset."""
    return directory / relative_pfm(sample)


def relative_pfm(sample: StereoSample) -> Path:
    """``REL/x.pfm`` for the sample whose left image is ``REL/x.png`` in its dataset: where its
    prediction lies in a predictions folder. SampleError when that would leave the folder."""
    rel = Path(str(sample.meta.get("left") or sample.name))
    if rel.is_absolute() or ".." in rel.parts:
        raise SampleError(f"sample path {rel} is not relative to the dataset")
    return rel.with_suffix(".pfm")


class NetworkRuns:
    """One forward pass of a fusion checkpoint per sample, shared by fusion, stereo and mono_align."""

    def __init__(self, checkpoint: Path, device: str, mono: Mono, iters: int | None, *,
                 label: str | None = None) -> None:
        from model.checkpoint import load_network
        from model.predictor import Predictor

        network, config, _payload = load_network(checkpoint, device, label=label)
        self.predictor = Predictor(network, config, device)
        self.config = config
        self.mono, self.iters = mono, iters
        self._last: tuple[str, Any] | None = None

    def __call__(self, sample: StereoSample) -> Any:
        if self._last is None or self._last[0] != sample.name:
            try:
                mono = self.mono(sample)
            except SampleError:
                mono = None  # a mono backend that estimates its own input does not need one
            try:
                prediction = self.predictor.predict(sample.left, sample.right, mono, iters=self.iters, seed=0)
            except ValueError as exc:
                raise SampleError(str(exc)) from None
            self._last = (sample.name, prediction)
        return self._last[1]


Predict = Callable[[StereoSample], np.ndarray]


def build_methods(names: list[str], *, checkpoint: Path | None, predictions: Path | None, mono_dir: Path | None,
                  align_rule: AlignRule = "lsq", sgbm: SgbmParams = SgbmParams(), device: str = "cpu",
                  iters: int | None = None, runs: NetworkRuns | None = None,
                  checkpoints: Mapping[str, Path] | None = None,
                  labels: Mapping[str, str] | None = None) -> dict[str, Predict]:
    """The predictors for ``names`` (report keys), each StereoSample → float32 HxW pixels at the
    sample's resolution. Raises ValueError naming what a method needs and was not given. A network
    method reads ``checkpoints[name]`` when given, else ``checkpoint``; ``runs``: a caller's own
    :class:`NetworkRuns` of ``checkpoint`` (to read more of each prediction, e.g. the confidence);
    ``labels``: how messages name each checkpoint file (by path)."""
    mono = Mono(mono_dir)
    methods: dict[str, Predict] = {}
    networks: dict[Path, NetworkRuns] = {checkpoint: runs} if runs is not None and checkpoint is not None else {}

    def network(name: str) -> NetworkRuns:
        path = (checkpoints or {}).get(name) or checkpoint
        if path is None and runs is not None:
            return runs
        if path is None:
            raise ValueError(f"{name.replace('_', '-')} needs a checkpoint (--checkpoint, or promote a run)")
        if path not in networks:  # methods naming one checkpoint share its forward pass
            networks[path] = NetworkRuns(path, device, mono, iters, label=(labels or {}).get(str(path)))
        architecture = networks[path].config.model.architecture
        baseline = BASELINE_METHODS.get(name)
        if baseline is not None and architecture != baseline.architecture:
            trained = ", or a raft-stereo run's" if baseline.architecture == "raft-stereo" else ""
            raise ValueError(f"{baseline.architecture} scores a {baseline.title} network's checkpoint (an imported "
                             f"one{trained}), not a {architecture} network's")
        return networks[path]

    for name in names:
        if name == "fusion":
            methods[name] = lambda s, r=network(name): r(s).disparity
        elif name == "stereo":
            methods[name] = lambda s, r=network(name): r(s).stereo
        elif name == "mono_align":
            methods[name] = lambda s, r=network(name): r(s).mono_align
        elif name in BASELINE_METHODS:
            methods[name] = lambda s, r=network(name): r(s).disparity
        elif name == "mono_gt_align":
            methods[name] = lambda s: _gt_aligned(s, mono(s), align_rule)
        elif name == "sgbm":
            methods[name] = lambda s: _sgbm(s, sgbm)
        elif name == "predictions":
            if predictions is None:
                raise ValueError("the predictions method needs --predictions DIR")
            methods[name] = lambda s, d=predictions: _read_prediction(d, s)
        else:
            raise ValueError(f"unknown method {name!r}")
    return methods


def _gt_aligned(sample: StereoSample, mono: np.ndarray, rule: AlignRule) -> np.ndarray:
    region = sample.regions.get("non_illusion", sample.regions["all"])
    mask = region & np.isfinite(sample.disparity)
    if not mask.any():
        raise SampleError("no valid non-illusion pixel to align the monocular disparity on")
    return align(mono, sample.disparity, mask, rule)


def _sgbm(sample: StereoSample, params: SgbmParams) -> np.ndarray:
    max_disparity = params.max_disparity or sgbm_max_disparity(sample.left.shape[1])
    raw = sgbm_disparity(sample.left, sample.right, max_disparity, block_size=params.block_size)
    return fill_holes(raw)


def _read_prediction(directory: Path, sample: StereoSample) -> np.ndarray:
    path = prediction_path(directory, sample)
    if not path.is_file():
        raise SampleError(f"no prediction {path}")
    try:
        disparity = read_pfm(path)
    except ValueError as exc:
        raise SampleError(str(exc)) from None
    if disparity.ndim != 2:
        raise SampleError(f"{path}: expected a single-channel disparity, got shape {disparity.shape}")
    h, w = sample.disparity.shape
    return resize_disparity(disparity, (h, w))
