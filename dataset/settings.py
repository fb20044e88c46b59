"""The one typed settings object of Illusion Studio.

Values come, highest priority first, from environment variables (``ILLUSION_STUDIO_*``), the
optional TOML file ``illusion-studio.toml`` in the data dir, and the defaults below. Only this
module reads the environment; everything else receives a :class:`Settings` instance.
"""

from __future__ import annotations

import ipaddress
import json
import os
import re
import tomllib
from pathlib import Path
from typing import Any, Literal

import limits
from pydantic import Field, ValidationError, field_validator, model_validator
from pydantic_settings import BaseSettings, EnvSettingsSource, PydanticBaseSettingsSource, SettingsConfigDict

ENV_PREFIX = "ILLUSION_STUDIO_"
HOME_ENV = ENV_PREFIX + "HOME"
SETTINGS_FILE = "illusion-studio.toml"
DATASET_ROOT_NAME = r"[A-Za-z0-9_.-]{1,64}"  # what a registered dataset root may be called
_ROOT_NAME = re.compile(DATASET_ROOT_NAME)


class SettingsError(ValueError):
    """A settings problem a user can fix; the message is one line naming it."""


class _EnvWithoutHome(EnvSettingsSource):
    """The environment's settings, less the data dir."""

    def __call__(self) -> dict[str, Any]:
        values = super().__call__()
        values.pop("home", None)
        return values


class Settings(BaseSettings):
    """Where the data lives, which services and model backends to use, where to listen."""

    model_config = SettingsConfigDict(env_prefix=ENV_PREFIX, extra="forbid", frozen=True)

    home: Path = Field(description="Data dir: database, queue, media, caches.")
    database_url: str = Field("", description="SQLAlchemy URL; default SQLite (WAL) in the data dir.")
    queue_url: str = Field("", description="redis://… for Redis; default a SQLite queue in the data dir.")
    queue_name: str = Field("illusion-studio", description="Queue (Redis key prefix); workers of one deployment share it.")
    queue_resend_after_s: float = Field(30.0, gt=0,
                                        description="Workers re-send a queued job whose message is missing this long.")
    media_gc_grace_hours: float = Field(24.0, ge=0, description="`media gc` keeps unreferenced files younger than this.")
    export_retention_days: float = Field(7.0, ge=0, description="Exports made on the Export page are deleted this long "
                                                                "after they were asked for; 0 keeps them until a curator "
                                                                "deletes them.")
    media_root: Path = Field(Path(), description="Content-addressed media store; default <home>/media.")
    host: str = "127.0.0.1"
    port: int = Field(5000, ge=1, le=65535)
    secret_key: str = Field("", description="Flask session key; default one generated into the data dir.")
    max_upload_mb: int = Field(2048, gt=0)
    # Security: server-side sessions, login and API-token throttling (limits' syntax: "10 per 15 minutes"), HTTPS.
    session_idle_minutes: int = Field(480, ge=1, description="A session unused this long ends.")
    session_lifetime_hours: int = Field(72, ge=1, description="A session ends this long after its login.")
    login_limit_per_account_address: str = Field(
        "10 per 15 minutes", description="Failed logins for one user name from one address; past it that address gets "
                                         "429 for that name, even with the right password.")
    login_slowdown_per_account: str = Field(
        "10 per 15 minutes", description="Failed logins for one user name from all addresses; past it its logins wait "
                                         "(never refused).")
    login_slowdown_per_address: str = Field(
        "50 per 15 minutes", description="Failed logins from one address for all names; past it its logins wait "
                                         "(never refused).")
    login_slowdown_max_s: float = Field(4.0, ge=0, le=30, description="Longest wait of a slowed-down login; waits "
                                                                       "start at 0.25 s and double per failure.")
    login_device_cookie_days: int = Field(
        365, ge=0, le=3650, description="Life of the signed cookie a login leaves for its user in that browser: later "
                                        "logins for that name carrying it are counted only against the cookie (failures "
                                        "as login_limit_per_account_address allows), not slowed or refused for others' "
                                        "failures; 0: no device cookies.")
    token_limit_per_address: str = Field(
        "50 per 15 minutes", description="Bad API tokens per client address; past it its bad tokens get 429 (a right "
                                         "token always passes).")
    token_limit_per_account: str = Field(
        "10 per 15 minutes", description="Wrong secrets for one user's API tokens (tokens ist_<id>_<secret> name their "
                                         "user; old ist_<secret> ones only count per address).")
    https: bool = Field(False, description="Served over HTTPS (behind a proxy): Secure cookies, HSTS.")
    trusted_proxies: list[ipaddress.IPv4Network | ipaddress.IPv6Network] = Field(
        default_factory=list, description="Reverse proxies' address ranges, e.g. [\"127.0.0.1/32\"]: from a peer in them the "
                                          "client's address is read from X-Forwarded-For (right to left, past trusted "
                                          "addresses); default none: the socket's peer is the client.")
    # Model backends: each has a weight-free default; the others load from a local directory.
    annotation_lease_s: int = Field(600, ge=30, description="How long a frame stays with an annotator without a renewal.")
    embedding_cache_mb: int = Field(2048, gt=0, description="Disk budget of the segmenter's embedding cache.")
    preview_cache_mb: int = Field(1024, gt=0, description="Disk budget of rendered previews (2D views, 3D scenes).")
    segmenter: Literal["classical", "sam2"] = "classical"
    sam2_model_path: Path | None = None
    depth_backend: Literal["precomputed", "depth-anything-v2"] = "precomputed"
    depth_model_path: Path | None = None
    vlm_backend: Literal["heuristic", "openai", "transformers"] = "heuristic"
    vlm_base_url: str = "http://127.0.0.1:8000/v1"
    vlm_model: str = "Qwen2-VL-72B-Instruct"
    vlm_api_key: str = ""
    vlm_model_path: Path | None = None
    # The keep rule (1-based question numbers; the authors' by default): keep if any of
    # keep_any_of is yes, and not (veto[0] yes and veto[1] no), and none of keep_none_of is yes.
    vlm_keep_any_of: tuple[int, ...] = (1, 2, 3, 4, 5, 6)
    vlm_keep_veto: tuple[int, int] | None = (7, 8)
    vlm_keep_none_of: tuple[int, ...] = (9, 10, 11, 12)
    # Generation (the authors' defaults) and the QA thresholds that flag a sample for a closer look.
    plane_threshold: float = Field(0.01, gt=0, description="RANSAC inlier threshold on min-max normalised disparity.")
    plane_hypotheses: int = Field(1000, ge=10)
    right_view_tau: float = Field(0.9, gt=0, le=1, description="Share of warped pixels that must stay inside the image.")
    qa_max_hole_fraction: float = Field(0.2, ge=0, le=1)
    qa_max_stereo_epe: float = Field(2.0, gt=0, description="Flag when SGBM disagrees by more than this (px).")
    qa_min_inlier_ratio: float = Field(0.5, ge=0, le=1)
    inpaint_backend: Literal["telea", "ns", "none", "lama"] = "telea"
    lama_model_path: Path | None = None
    device: str = Field("cpu", description="torch device for model backends: cpu, cuda, cuda:1 …")
    proposers: list[Literal["plane-break", "vlm"]] = Field(
        default_factory=lambda: ["plane-break"],
        description="Illusion proposers run on frames to annotate: plane-break (no weights), vlm (the VLM backend).")
    # plane-break's DEFAULT_THRESHOLD (a test holds them equal): importing it here would load OpenCV with the settings.
    proposal_threshold: float = Field(
        0.5, ge=0, le=1,
        description="Proposals scoring under this are hidden on the Annotate page unless \"show all\" is on.")
    # What the web may name and launch: dataset folders only inside these roots (by name), and
    # training runs within what a train worker's machine holds (each worker checks its own again).
    dataset_roots: dict[str, Path] = Field(
        default_factory=dict, description="Dataset folders the web may name: {name: folder}; a request names "
                                          "a root by name and a relative path inside it.")
    train_max_nproc: int = Field(default_factory=lambda: os.cpu_count() or 1, ge=1, le=1024,
                                 description="Most trainer processes a web launch may ask for.")
    train_devices: Literal["cpu", "cuda"] = Field(
        default_factory=lambda: _default_train_devices(),
        description="What train workers have: cpu, or cuda (then cpu runs are allowed too).")
    train_memory_gb: float = Field(default_factory=lambda: _machine_memory_gb(), gt=0,
                                   description="Memory a run may use; launches estimated above it are refused.")

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        # Init kwargs carry the TOML file's values, so the environment must rank above them —
        # but for the data dir, which load_settings resolves (--data-dir before $ILLUSION_STUDIO_HOME).
        return _EnvWithoutHome(settings_cls), init_settings

    @field_validator("dataset_roots")
    @classmethod
    def _roots(cls, value: dict[str, Path]) -> dict[str, Path]:
        for name, folder in value.items():
            if not _ROOT_NAME.fullmatch(name):
                raise ValueError(f"dataset root name {name!r}: letters, digits, '-', '_' and '.' only")
            if not folder.is_absolute():
                raise ValueError(f"dataset root {name!r}: {folder} must be an absolute path")
        return {name: folder.expanduser().resolve() for name, folder in value.items()}

    @field_validator("login_limit_per_account_address", "login_slowdown_per_account", "login_slowdown_per_address",
                     "token_limit_per_address", "token_limit_per_account")
    @classmethod
    def _rate_limit(cls, value: str) -> str:
        try:
            limits.parse(value)
        except ValueError:
            raise ValueError(f"{value!r} is not a rate limit like '10 per 15 minutes'") from None
        return value

    @field_validator("trusted_proxies", mode="before")
    @classmethod
    def _networks(cls, value: Any) -> Any:
        if not isinstance(value, list | tuple):
            return value  # pydantic names the wrong type
        networks = []
        for item in value:
            try:
                networks.append(ipaddress.ip_network(str(item).strip()))
            except ValueError as exc:
                raise ValueError(f"{exc}; write an address range like '10.0.0.0/8' or an address like '127.0.0.1'") from None
        return networks

    @model_validator(mode="after")
    def _fill_paths(self) -> Settings:
        home = self.home.expanduser().resolve()
        object.__setattr__(self, "home", home)
        if not self.database_url:
            object.__setattr__(self, "database_url", f"sqlite:///{home / 'illusion-studio.db'}")
        media = self.media_root if str(self.media_root) not in ("", ".") else home / "media"
        object.__setattr__(self, "media_root", media.expanduser().resolve())
        return self

    @property
    def queue_path(self) -> Path:
        """SQLite file of the default job queue."""
        return self.home / "queue.db"

    @property
    def cache_dir(self) -> Path:
        return self.home / "cache"

    @property
    def runs_dir(self) -> Path:
        """Training runs, one directory per run id."""
        return self.home / "runs"

    @property
    def exports_dir(self) -> Path:
        """Exports made on the Export page, one folder per export id."""
        return self.home / "exports"

    @property
    def models_dir(self) -> Path:
        """The current model's pointer (``current.json``)."""
        return self.home / "models"


def _machine_memory_gb() -> float:
    """This machine's physical memory in GiB."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30


def _default_train_devices() -> Literal["cpu", "cuda"]:
    """cuda where an NVIDIA driver is present (without importing torch), else cpu."""
    return "cuda" if Path("/proc/driver/nvidia/version").is_file() else "cpu"


def load_settings(
    data_dir: Path | str | None = None,
    *,
    must_exist: bool = True,
    **overrides: Any,
) -> Settings:
    """Build the settings for ``data_dir`` (default ``$ILLUSION_STUDIO_HOME``).

    Raises :class:`SettingsError` with a one-line message for a missing data dir, an unreadable
    or invalid TOML file, or an invalid value.
    """
    raw_home = data_dir if data_dir is not None else os.environ.get(HOME_ENV)
    if not raw_home:
        raise SettingsError(f"no data dir: pass --data-dir DIR or set {HOME_ENV}")
    home = Path(raw_home).expanduser()
    if must_exist and not home.is_dir():
        raise SettingsError(f"data dir {home} does not exist; run `illusion-studio --data-dir {home} init`")
    values: dict[str, Any] = {}
    toml_file = home / SETTINGS_FILE
    if toml_file.is_file():
        try:
            values = tomllib.loads(toml_file.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise SettingsError(f"{toml_file}: not valid TOML: {exc}") from None
    values.update(overrides)
    values["home"] = home
    try:
        return Settings(**values)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in err["loc"]) or "settings"
        source = toml_file if toml_file.is_file() else "environment"
        raise SettingsError(f"{source}: {where}: {err['msg']}") from None


def drop_settings_environment() -> list[str]:
    """Remove every ``ILLUSION_STUDIO_*`` variable from this process's environment (and so from the
    processes it starts); returns their names. For scratch workspaces, such as the benchmarks',
    whose settings files the environment would otherwise outrank."""
    names = sorted(name for name in os.environ if name.startswith(ENV_PREFIX))
    for name in names:
        del os.environ[name]
    return names


def write_settings_file(home: Path, **values: Any) -> None:
    """Write ``values`` as the data dir's settings file, which every process started on ``home`` reads
    (None values are left out: TOML has no null)."""
    lines = [f"{key} = {_toml_value(value)}\n" for key, value in values.items() if value is not None]
    (home / SETTINGS_FILE).write_text("".join(lines), encoding="utf-8")


def _toml_value(value: Any) -> str:
    """TOML for the values settings take: basic strings and arrays share JSON's syntax; tables
    (``dataset_roots``) are written inline."""
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml_value(v)}" for k, v in value.items()) + " }"
    return json.dumps(str(value) if isinstance(value, Path) else value)
