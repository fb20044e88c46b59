"""The synthetic scene families (dataset.synthetic.layout, families=True): every illusion's frame from one
distribution whatever its kind, large mirrors, mirrored front walls, textureless and repetitive walls, and
estimators that read a mirror as a surface beside ones it fools — while the scenes without families stay
as they were."""

from __future__ import annotations

import numpy as np
import pytest

from dataset.synthetic import layout as L
from dataset.synthetic.io import read_video, write_video
from dataset.synthetic.mono import MIRROR_FRACTION, MIRROR_FRACTION_FAMILIES, sample_mono_model
from dataset.synthetic.render import render_video
from dataset.synthetic.textures import FLAT, texture_index

SEEDS = range(5_000, 5_060)


def _frame_width(layout: L.Layout, index: int) -> float:
    """The frame's width (m) around rect ``index`` (0: the picture, 1: the mirror)."""
    frame, canvas = layout.scene.rects[index], layout.scene.rects[index + 2]
    return canvas.lo[0] - frame.lo[0]


def test_frames_come_from_one_distribution_for_both_kinds_and_mirrors_may_be_large() -> None:
    layouts = [L.sample_layout(seed, families=True) for seed in SEEDS]
    widths = np.array([[_frame_width(layout, k) for k in (0, 1)] for layout in layouts])
    present = widths > 0
    for kind in (0, 1):  # the picture's frames and the mirror's: alike
        assert abs(present[:, kind].mean() - L.FRAME_PRESENT) < 0.17, present.mean(axis=0)
        framed = widths[present[:, kind], kind]
        assert L.FRAME_WIDTH_M[0] <= framed.min() and framed.max() <= L.FRAME_WIDTH_M[1]
    tints = {layout.scene.materials[layout.scene.rect_sid(k)].tint for layout in layouts for k in (0, 1)}
    assert len(tints) >= 5  # frame colours are not the kind's
    wall = np.array([_is_front_wall(layout) for layout in layouts])
    assert 0.3 <= wall.mean() <= L.MIRROR_WALL, wall.mean()  # the share drawn, less rooms whose sides hold no picture
    large = np.array([layout.mirror.size[0] >= L.LARGE_MIRROR_M[0][0] for layout in layouts])[~wall]
    assert 0.3 <= large.mean() <= 0.7, large.mean()
    flat = texture_index(FLAT)
    walls = [layout.scene.materials[face].tile for layout in layouts for face in (0, 1, 4, 5)]
    assert 0.15 <= np.mean([tile == flat for tile in walls]) <= 0.45


def _is_front_wall(layout: L.Layout) -> bool:
    lo, hi = layout.scene.room_lo, layout.scene.room_hi
    return layout.mirror == L.Rect(5, (lo[0], lo[1]), (hi[0], hi[1]))


def test_a_mirrored_front_wall_fools_stereo_over_all_of_it() -> None:
    seed = next(seed for seed in SEEDS if _is_front_wall(L.sample_layout(seed, families=True)))
    layout = L.sample_layout(seed, families=True)
    assert layout.picture.face in (0, 1)  # the picture moved to a side wall
    frame = render_video(seed, 1, 160, 96, families=True).frames[0]
    (mirror,) = [pair for pair in frame.regions if pair.illusion_type == "mirror"]
    assert mirror.illusion.mean() > 0.1 and not mirror.support.any()  # no wall around the glass
    # a matcher that finds the reflection sees the room go on behind the glass: the side walls, floor and
    # ceiling meet their reflections at its edges, the room behind the camera lies twice as far
    glass = frame.disparity[mirror.illusion]
    behind = (glass - frame.stereo_disparity[mirror.illusion]) / glass
    assert behind.min() >= 0 and np.median(behind) > 0.2 and np.percentile(behind, 95) > 0.4, np.percentile(behind, [50, 95])


def test_without_families_a_seed_is_the_scene_it_was() -> None:
    for seed in (0, 2, 41):
        plain = L.sample_layout(seed)
        assert all(_frame_width(plain, k) == pytest.approx(L.FRAME_M) for k in (0, 1))
        assert plain.scene.materials[plain.scene.rect_sid(0)].tint == L._PICTURE_FRAME_TINT
        assert MIRROR_FRACTION[0] <= sample_mono_model(seed).mirror_fraction <= MIRROR_FRACTION[1]
    # the family scene is the seed's room: same walls' place, camera and picture
    plain, family = L.sample_layout(7), L.sample_layout(7, families=True)
    assert not _is_front_wall(family)  # (a mirrored wall sends the picture to a side wall)
    assert plain.scene.room_lo == family.scene.room_lo and plain.trajectory == family.trajectory
    assert plain.picture == family.picture


def test_half_the_estimators_read_a_mirror_as_a_surface(tmp_path) -> None:  # type: ignore[no-untyped-def]
    fractions = np.array([sample_mono_model(seed, families=True).mirror_fraction for seed in SEEDS])
    reads, fooled = MIRROR_FRACTION_FAMILIES
    surface = (reads[0] <= fractions) & (fractions <= reads[1])
    assert np.all(surface | ((fooled[0] <= fractions) & (fractions <= fooled[1])))
    assert 0.3 <= surface.mean() <= 0.7
    video = render_video(SEEDS[0], 1, 64, 48, families=True)
    assert video.name == f"synthetic-families-{SEEDS[0]:04d}" and video.families
    assert read_video(write_video(video, tmp_path)).families is True
