"""`illusion-studio synth` ends with one line saying what it made, on stderr: stdout stays the list
of the videos' folders, one a line, for scripts."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.test_cli import cli


@pytest.mark.parametrize(("videos", "seed", "said"), [
    ("3", "0", "made 3 videos, 6 frames, 96×64, seeds 0–2 in {out}"),
    ("1", "5", "made 1 video, 2 frames, 96×64, seed 5 in {out}"),
])
def test_synth_says_what_it_made(tmp_path: Path, videos: str, seed: str, said: str) -> None:
    out = tmp_path / "out"
    result = cli("synth", str(out), "--videos", videos, "--seed", seed, "--frames", "2", "--size", "96x64")
    assert result.returncode == 0, result.stderr
    folders = result.stdout.splitlines()
    assert len(folders) == int(videos) and all((Path(f) / "scene.json").is_file() for f in folders)
    assert result.stderr.strip().splitlines()[-1] == said.format(out=out)
