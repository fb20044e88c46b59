"""The media store: content addressing, atomic writes, no escape from the root, login-only serving."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from core.atomic import atomic_write_bytes
from dataset.media import MediaKeyError, MediaStore


def test_put_is_content_addressed_and_idempotent(tmp_path: Path) -> None:
    store = MediaStore(tmp_path)
    key = store.put_bytes(b"hello", "PNG")
    assert key == store.put_bytes(b"hello", ".png")
    assert key.endswith(".png") and store.read_bytes(key) == b"hello"
    assert store.put_bytes(b"other", "png") != key
    assert not list(tmp_path.rglob("*.tmp")), "temporary files left behind"


def test_atomic_write_keeps_the_old_file_when_the_write_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "f.bin"
    atomic_write_bytes(target, b"old")

    def boom(*_a: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError, match="disk full"):
        atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.bin"]


@pytest.mark.parametrize("key", [
    "../etc/passwd", "ab/cd/../../../etc/passwd", "/etc/passwd", "ab/cd/" + "0" * 64,
    "ab/cd/" + "g" * 64 + ".png", "ab/cd/" + "a" * 64 + ".png/../../x", "", "ab\\cd\\" + "a" * 64 + ".png",
])
def test_keys_that_are_not_store_keys_are_refused(tmp_path: Path, key: str) -> None:
    with pytest.raises(MediaKeyError):
        MediaStore(tmp_path).path(key)


@given(st.text(max_size=120))
def test_no_string_resolves_outside_the_root(key: str) -> None:
    root = Path("/tmp/illusion-media-root-prop")
    store = MediaStore(root)
    try:
        path = store.path(key)
    except MediaKeyError:
        return
    assert path.is_relative_to(store.root)


def test_symlinked_directory_cannot_leak(tmp_path: Path) -> None:
    root, outside = tmp_path / "media", tmp_path / "outside"
    (root / "ab").mkdir(parents=True)
    (outside / "cd").mkdir(parents=True)
    (root / "ab" / "cd").symlink_to(outside / "cd")
    with pytest.raises(MediaKeyError, match="leaves the media root"):
        MediaStore(root).path("ab/cd/" + "ab" * 32 + ".png")


def test_served_to_logged_in_users_only(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    key = runtime.media.put_bytes(b"\x89PNG fake", "png")
    assert client.get(f"/media/{key}").status_code == 302  # to the login page
    auth = {"Authorization": f"Bearer {tokens['annotator']}"}
    response = client.get(f"/media/{key}", headers=auth)
    assert response.status_code == 200 and response.data == b"\x89PNG fake"
    assert "max-age" in response.headers["Cache-Control"]
    for attack in ("../secret_key", "..%2f..%2fsecret_key", "%2e%2e/%2e%2e/secret_key",
                   "ab/cd/" + "a" * 64 + ".png%00", "/etc/passwd"):
        response = client.get(f"/media/{attack}", headers=auth, follow_redirects=True)
        assert response.status_code in (400, 404), attack  # a null byte is a 400 everywhere
        assert b"secret" not in response.data


def test_put_stream_matches_put_bytes_and_leaves_no_partial_files(tmp_path: Path) -> None:
    import io

    store = MediaStore(tmp_path)
    data = bytes(range(256)) * 9000  # several read chunks
    key = store.put_stream(io.BytesIO(data), "mp4")
    assert key == store.key_for(data, "mp4") and store.read_bytes(key) == data
    assert store.put_stream(io.BytesIO(data), "mp4") == key
    assert list((tmp_path / ".incoming").iterdir()) == []
