"""Settings: defaults, the TOML file, environment overrides, and clear errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from dataset.settings import SettingsError, load_settings


def test_defaults_live_in_the_data_dir(tmp_path: Path) -> None:
    s = load_settings(tmp_path)
    assert s.home == tmp_path.resolve()
    assert s.database_url == f"sqlite:///{tmp_path.resolve() / 'illusion-studio.db'}"
    assert s.media_root == tmp_path.resolve() / "media"
    assert s.host == "127.0.0.1" and s.segmenter == "classical" and s.inpaint_backend == "telea"


def test_toml_then_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "illusion-studio.toml").write_text('port = 6001\nsegmenter = "sam2"\nsam2_model_path = "/models/sam2"\n')
    s = load_settings(tmp_path)
    assert (s.port, s.segmenter, str(s.sam2_model_path)) == (6001, "sam2", "/models/sam2")
    monkeypatch.setenv("ILLUSION_STUDIO_PORT", "7002")
    assert load_settings(tmp_path).port == 7002


def test_home_from_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ILLUSION_STUDIO_HOME", str(tmp_path))
    assert load_settings().home == tmp_path.resolve()


@pytest.mark.parametrize(("content", "message"), [
    ("port = [", "not valid TOML"),
    ("port = 0", "port"),
    ('segmenter = "magic"', "segmenter"),
    ("no_such_setting = 1", "no_such_setting"),
    ('trusted_proxies = ["10.0.0.5/8"]', r"trusted_proxies: .*host bits set; write an address range like '10.0.0.0/8'"),
    ('trusted_proxies = ["proxy.example"]', "trusted_proxies: .*does not appear to be an IPv4 or IPv6 network"),
])
def test_bad_settings_file_is_one_clear_line(tmp_path: Path, content: str, message: str) -> None:
    (tmp_path / "illusion-studio.toml").write_text(content)
    with pytest.raises(SettingsError, match=message) as info:
        load_settings(tmp_path)
    assert "\n" not in str(info.value)


def test_missing_data_dir(tmp_path: Path) -> None:
    with pytest.raises(SettingsError, match="does not exist; run `illusion-studio --data-dir"):
        load_settings(tmp_path / "absent")
    with pytest.raises(SettingsError, match="no data dir"):
        load_settings(None)
