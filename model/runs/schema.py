"""The one typed schema of a launch — a training run or an evaluation — that the API, the Models
and Evaluation forms and the command line all validate through, and the OpenAPI document publishes.

A launch names only what the app knows: a run and one of its checkpoints by name, a dataset root
an admin registered plus a relative path inside it. Numbers are strict (no booleans, no strings,
no Unicode digits) and bounded by what a machine can hold; what depends on the machine (processes,
devices) is checked against the settings passed as validation context. What depends on the data
and memory is checked by :mod:`model.runs.capacity` once the data is pinned.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from dataset.export.splits import MIN_FRACTION
from dataset.imported import depth_model_dir
from dataset.readers import READER_FORMATS
from dataset.services.errors import FieldError, InvalidInput, ServiceError
from dataset.services.training import DEFAULT_SPLIT, SAMPLE_KINDS, parse_split
from dataset.services.validate import DB_INT_MAX
from dataset.settings import DATASET_ROOT_NAME
from dataset.tables import IllusionType
from model.align import ALIGN_RULES
from model.evaluate import RESOLUTIONS
from model.methods import METHODS, NETWORK_METHODS, method_key
from model.presets import ALL_PRESETS, PRESETS, Config, load_preset
from model.runs import registry
from model.train.spec import BACKBONES

MAX_STEPS = 1_000_000  # 10× the paper's 100k
MAX_BATCH = 256
MAX_ITERS = 64  # GRU iterations (the paper: 16–22 in training, 32 at test)
MAX_SIDE = 8192  # pixels of a crop side
SEED_MAX = 2**32 - 1
MAX_DISPARITY = 4096  # pixels, SGBM's search range
# The smallest peak learning rate. An Adam step is about lr in size, and float32 weights near 0.1 are
# 7.5e-9 apart: smaller steps are mostly rounded away (5e-324 parses, and trains nothing).
MIN_LR = 1e-8

Id = Annotated[int, Field(ge=1, le=DB_INT_MAX)]
_ROOT = f"^{DATASET_ROOT_NAME}$"
_CHECKPOINT_NAME = r"^(best|last|best\.pt|(step|best_step)_[0-9]{7,12}\.pt)$"
_CROP_TEXT = re.compile(r"([0-9]{1,5})[xX×]([0-9]{1,5})")
_DEVICES = r"^(auto|cpu|cuda|cuda:[0-9]{1,3}(,[0-9]{1,3}){0,63})$"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class CheckpointRef(_Strict):
    """A run's checkpoint by name: ``best``, ``last`` or a file of its checkpoint list (the object form
    of ``RUN:NAME``, which earlier releases' forms send)."""

    run: Id
    checkpoint: str = Field("best", pattern=_CHECKPOINT_NAME,
                            description="best, last, or a file name from the run's checkpoints")

    @property
    def name(self) -> str:
        """The same checkpoint as :func:`model.runs.registry.resolve` names it (``3:best``)."""
        return f"{self.run}:{self.checkpoint}"


# What model.runs.registry.resolve takes from a request (never a path): RUN:NAME or imported:NAME.
_NAMED = r"^([1-9][0-9]{0,9}:(best|last|best\.pt|(step|best_step)_[0-9]{7,12}\.pt)|imported:[A-Za-z0-9][A-Za-z0-9._-]{0,63})$"
_IMPORTED = r"^imported:[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"
CheckpointName = Annotated[str, Field(pattern=_NAMED, description=registry.NAME_HINT)]
_TAGS = ("checkpoint-name", "checkpoint-object")  # which form a checkpoint came in: no field of its own
Checkpoint = Annotated[Annotated[CheckpointName, Tag(_TAGS[0])] | Annotated[CheckpointRef, Tag(_TAGS[1])],
                       Discriminator(lambda v: _TAGS[1] if isinstance(v, dict | CheckpointRef) else _TAGS[0])]


def checkpoint_text(ref: Checkpoint) -> str:
    """A checkpoint of a request as one name for :func:`model.runs.registry.resolve`."""
    return ref.name if isinstance(ref, CheckpointRef) else ref


class FolderRef(_Strict):
    """A folder inside a dataset root an admin registered (settings ``dataset_roots``)."""

    root: str = Field(pattern=_ROOT, description="the registered root's name")
    path: str = Field("", max_length=1024, description="relative path inside the root ('' for the root)")


class FolderData(FolderRef):
    """A dataset folder and its layout."""

    format: Literal[READER_FORMATS]  # type: ignore[valid-type]


def _crop_text(value: Any) -> Any:
    """``"320x736"`` (the form's spelling) → ``[320, 736]``; anything else is left to the schema."""
    if isinstance(value, str):
        match = _CROP_TEXT.fullmatch(value.strip())
        if match is None:
            raise ValueError("expected HxW in pixels, e.g. 192x320")
        return [int(match.group(1)), int(match.group(2))]
    return value


Side = Annotated[int, Field(ge=1, le=MAX_SIDE)]
Crop = Annotated[list[Side], Field(min_length=2, max_length=2), BeforeValidator(_crop_text)]
Method = Annotated[Literal[tuple(sorted({*METHODS, *(m.replace("_", "-") for m in METHODS)}))],  # type: ignore[misc]
                   AfterValidator(method_key)]
# Keys earlier releases took, which named server paths; each now has a message saying what to send.
_RETIRED = {
    "data_root": "name a registered dataset root instead: data = {root, path, format}",
    "format": "give the folder's format inside data = {root, path, format}",
    "init_checkpoint": "name a run's checkpoint instead: init = RUN:NAME (or imported:NAME)",
    "nnodes": "multi-node runs are launched from the command line",
    "rdzv_endpoint": "multi-node runs are launched from the command line",
    "out": "reports are written to the workspace",
}


def _refuse_retired(data: Any, keys: tuple[str, ...]) -> Any:
    if isinstance(data, dict):
        for key in keys:
            if key in data:
                raise FieldError(key, f"not accepted: {_RETIRED[key]}")
    return data


def _settings(info: ValidationInfo) -> Any:
    return (info.context or {}).get("settings")


def backbone_dirs(config: Config, settings: Any) -> dict[str, str]:
    """The directories of the frozen backbones ``config``'s model loads, by config field, from
    ``settings`` (``depth_model_path``, ``vlm_model_path``; an ``imported:NAME`` depth model resolved to
        its directory); FieldError on ``preset`` naming the first setting that is not set or names no import.
    Whether each is a directory is the train worker's check, on its own."""
    model = config.model
    loads = {"mono_model_path": model.mono_backend == "depth-anything-v2",
             "vlm_model_path": model.use_vlm and model.vlm_backend == "qwen2-vl"}
    found = {}
    for field, weights, setting in BACKBONES:
        if loads[field]:
            directory = getattr(settings, setting, None)
            if not directory:
                raise FieldError("preset", f"{config.preset} loads {weights} weights from the directory the setting "
                                           f"{setting} names, and it is not set")
            if setting == "depth_model_path":  # may name an import: imported:NAME, this workspace's directory
                try:
                    directory = depth_model_dir(settings)
                except ServiceError as exc:
                    raise FieldError("preset", str(exc)) from None
            found[field] = str(directory)
    return found


class RunLaunch(_Strict):
    """A training run: preset and training overrides, processes and devices, data, start weights."""

    preset: Literal[tuple(ALL_PRESETS)] = "lite"  # type: ignore[valid-type]
    steps: int | None = Field(None, ge=1, le=MAX_STEPS, description="training steps (preset's by default)")
    batch: int | None = Field(None, ge=1, le=MAX_BATCH, description="global batch size")
    lr: float | None = Field(None, ge=MIN_LR, le=1, description="peak learning rate")
    crop: Crop | None = Field(None, description="random crop [H, W] (or 'HxW') in pixels, multiples of the "
                                                "model's size multiple, within the smallest image of the data")
    iters: int | None = Field(None, ge=1, le=MAX_ITERS, description="GRU iterations in training")
    nproc: int = Field(1, ge=1, le=1024, description="trainer processes (at most the settings' train_max_nproc)")
    devices: str = Field("auto", pattern=_DEVICES, description="auto, cpu, cuda or cuda:0,1")
    split: str = Field(DEFAULT_SPLIT, max_length=200, description="fractions of scene groups in train/val/test, "
                                                                 f"each 0 or at least {MIN_FRACTION}")
    seed: int = Field(0, ge=0, le=SEED_MAX)
    video_ids: list[Id] = Field(default_factory=list, max_length=100_000)
    illusion_types: list[Literal[tuple(t.value for t in IllusionType)]] = Field(  # type: ignore[misc]
        default_factory=list, max_length=len(IllusionType))
    kinds: list[Literal[SAMPLE_KINDS]] = Field(default_factory=list, max_length=len(SAMPLE_KINDS))  # type: ignore[valid-type]
    qa_ok: bool = False
    data: FolderData | None = Field(None, description="a dataset folder instead of the database's accepted samples")
    init: Checkpoint | None = Field(None, description="start from this checkpoint's weights (fine-tuning): "
                                                       "RUN:NAME, imported:NAME, or {run, checkpoint}")
    init_stereo: str | None = Field(None, pattern=_IMPORTED, description="start the paper network's stereo branch from this "
                                                                 "RAFT-Stereo checkpoint (imported:NAME): the tensors "
                                                                 "that fit load, the rest start fresh")

    @model_validator(mode="before")
    @classmethod
    def _retired(cls, data: Any) -> Any:
        return _refuse_retired(data, ("data_root", "format", "init_checkpoint", "nnodes", "rdzv_endpoint"))

    @field_validator("split")
    @classmethod
    def _split(cls, value: str) -> str:
        try:
            parse_split(value)
        except InvalidInput as exc:
            raise ValueError(str(exc).removeprefix("split: ")) from None
        return value

    @field_validator("nproc")
    @classmethod
    def _nproc(cls, value: int, info: ValidationInfo) -> int:
        settings = _settings(info)
        if settings is not None and value > settings.train_max_nproc:
            raise ValueError(f"at most {settings.train_max_nproc} processes on this deployment (train_max_nproc)")
        return value

    @field_validator("devices")
    @classmethod
    def _devices(cls, value: str, info: ValidationInfo) -> str:
        settings = _settings(info)
        if settings is not None and value.startswith("cuda") and settings.train_devices != "cuda":
            raise ValueError("this deployment's train workers have no GPU (train_devices = cpu): use auto or cpu")
        return value

    @model_validator(mode="after")
    def _data_or_filters(self) -> RunLaunch:
        if self.data is not None and (self.video_ids or self.illusion_types or self.kinds or self.qa_ok):
            raise FieldError("data", "video, illusion type, kind and QA filters select from the database, "
                                     "not from a folder")
        return self

    @model_validator(mode="after")
    def _stereo_start(self) -> RunLaunch:
        if self.init_stereo is not None and self.preset not in PRESETS:
            raise FieldError("init_stereo", f"{self.preset} is RAFT-Stereo's own network: start it with init")
        if self.init_stereo is not None and self.init is not None:
            raise FieldError("init_stereo", "init already starts every weight: choose one of init and init_stereo")
        return self

    @model_validator(mode="after")
    def _weights_configured(self, info: ValidationInfo) -> RunLaunch:
        # A preset whose backbones load from directories cannot start where no setting names them.
        settings = _settings(info)
        if settings is not None:
            backbone_dirs(load_preset(self.preset), settings)
        return self

    def overrides(self) -> dict[str, Any]:
        """The preset overrides (dotted TrainConfig names) this launch asks for."""
        values = {"train.steps": self.steps, "train.batch_size": self.batch, "train.lr": self.lr,
                  "train.crop": tuple(self.crop) if self.crop else None, "train.train_iters": self.iters,
                  "train.seed": self.seed}
        return {key: value for key, value in values.items() if value is not None}


class EvaluationLaunch(_Strict):
    """An evaluation: methods, the checkpoint they use, and the samples (a dataset folder, or the
    held-out test split of a run)."""

    methods: list[Method] = Field(default_factory=list, max_length=len(METHODS), description="methods to score")
    checkpoint: Checkpoint | None = Field(None, description="for fusion, stereo and mono-align: RUN:NAME, "
                                                            "imported:NAME or {run, checkpoint} (default: the current model)")
    checkpoints: dict[Method, CheckpointName] = Field(  # type: ignore[valid-type]
        default_factory=dict, max_length=len(NETWORK_METHODS),
        description="a checkpoint per network method (raft-stereo, selective-raft and selective-igev need one), "
                    "over checkpoint")
    run: Id | None = Field(None, description="a run whose held-out test split to evaluate on "
                                             "(default: the checkpoint's run)")
    data: FolderData | None = Field(None, description="a dataset folder instead of a run's test split")
    predictions: FolderRef | None = Field(None, description="another program's PFMs, for the predictions method")
    mono: FolderRef | None = Field(None, description="monocular disparities (PFMs), for data that carries none")
    resolution: Literal[tuple(RESOLUTIONS)] | None = None  # type: ignore[valid-type]
    align: Literal[ALIGN_RULES] = "lsq"  # type: ignore[valid-type]
    max_disparity: int | None = Field(None, ge=1, le=MAX_DISPARITY, description="SGBM's search range, pixels")
    kitti_png: bool = False
    iters: int | None = Field(None, ge=1, le=MAX_ITERS, description="GRU iterations")

    @model_validator(mode="before")
    @classmethod
    def _retired(cls, data: Any) -> Any:
        return _refuse_retired(data, ("format", "out"))

    @model_validator(mode="after")
    def _consistent(self) -> EvaluationLaunch:
        if not self.methods:
            raise FieldError("methods", "tick at least one method to score")
        if len(set(self.methods)) != len(self.methods):
            raise FieldError("methods", "a method is named twice")
        if self.predictions is not None and "predictions" not in self.methods:
            raise FieldError("predictions", "a predictions folder is read only by the predictions method")
        for method in self.checkpoints:
            if method not in self.methods or method not in NETWORK_METHODS:
                raise FieldError("checkpoints", f"{method.replace('_', '-')} is not a network method of this evaluation")
        if self.data is not None and self.run is not None:
            raise FieldError("run", "choose a dataset folder or a run's test split, not both")
        return self

    @property
    def needs_network(self) -> bool:
        return any(m in NETWORK_METHODS for m in self.methods)


def validate(schema: type[_Strict], body: Any, settings: Any = None) -> Any:
    """``body`` (a request's JSON, or the command line's values) as ``schema``; FieldError naming
    the first wrong field and why, in the schema's words."""
    if not isinstance(body, dict):
        raise FieldError("", "expected a JSON object")
    try:
        return schema.model_validate(body, context={"settings": settings})
    except ValidationError as exc:
        error = exc.errors(include_url=False, include_input=False)[0]
        # A list's item is its list's field (what a form marks): crop, not crop.0.
        field = ".".join(str(p) for p in error["loc"] if not isinstance(p, int) and p not in _TAGS)
        raise FieldError(field, _reason(error)) from None


_WORDS = {"less_than_equal": "must be at most {le}", "less_than": "must be less than {lt}",
          "greater_than_equal": "must be at least {ge}", "greater_than": "must be more than {gt}",
          "int_type": "must be an integer", "int_parsing": "must be an integer", "float_type": "must be a number",
          "finite_number": "must be a finite number", "bool_type": "must be true or false",
          "string_type": "must be text", "list_type": "must be a list", "model_type": "must be an object",
          "literal_error": "must be one of {expected}", "extra_forbidden": "is not a field of this launch",
          "too_short": "needs at least {min_length} item(s)", "too_long": "takes at most {max_length} item(s)",
          "missing": "is required"}
_PATTERNS = {_CHECKPOINT_NAME: "expected best, last or a checkpoint file name such as step_0001000.pt",
             _NAMED: f"expected {registry.NAME_HINT}",
             _IMPORTED: "expected imported:NAME (`illusion-studio checkpoints import` adds one)",
             _ROOT: "expected a registered dataset root's name", _DEVICES: "expected auto, cpu, cuda or cuda:0,1"}


def _reason(error: dict[str, Any]) -> str:
    """The reason in the form's words (pydantic's own message where there is none)."""
    ctx = error.get("ctx") or {}
    if error["type"] == "string_pattern_mismatch":
        return _PATTERNS.get(ctx.get("pattern", ""), "has an unexpected form")
    words = _WORDS.get(error["type"])
    return words.format(**ctx) if words else str(error["msg"]).removeprefix("Value error, ")


def openapi_schemas() -> dict[str, Any]:
    """The launch schemas as OpenAPI 3.1 components (JSON Schema), their references rewritten."""
    out: dict[str, Any] = {}
    for schema in (RunLaunch, EvaluationLaunch):
        document = schema.model_json_schema(ref_template="#/components/schemas/{model}")
        out.update(document.pop("$defs", {}))
        out[schema.__name__] = document
    return out
