"""The classical segmenter on a synthetic room's back wall with boxes standing in front of it: a
click on the wall must not spread onto a box, and a right-click on a box that a previous mask
leaked onto removes the whole box, its top included.

The ground truth comes from the renderer's own ray cast: which room face, box or wall rectangle
the ray through each pixel centre meets first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from annotation.segment import Embedding, make_segmenter
from benchmarks.segment import person_click
from dataset.synthetic import render_video
from dataset.synthetic.layout import sample_layout
from dataset.synthetic.raycast import N_FACES, View, trace
from dataset.synthetic.render import intrinsics

SIZE = (1280, 720)
BACK_WALL = 5  # room face z max, facing the camera
BOX_TOP = 1  # a box face's normal axis: y, the one seen from above


@dataclass
class Scene:
    """Frame 0 of a seed: its left image and, per pixel, the room face (-1 on boxes) and surface id
    of the first surface hit."""

    image: np.ndarray
    face: np.ndarray
    sid: np.ndarray

    @property
    def plane(self) -> np.ndarray:
        """The back wall's plane, with the picture or mirror hung on it."""
        return self.face == BACK_WALL

    @property
    def wall(self) -> np.ndarray:
        """The bare back wall: what a support click on it should select."""
        return self.sid == BACK_WALL

    def box(self, k: int) -> np.ndarray:
        return (self.sid >= N_FACES + 3 * k) & (self.sid < N_FACES + 3 * k + 3)

    def box_face(self, k: int, axis: int) -> np.ndarray:
        return self.sid == N_FACES + 3 * k + axis


def render(seed: int) -> Scene:
    layout = sample_layout(seed)
    f, cx, cy = intrinsics(*SIZE)
    center, rotation = layout.trajectory.pose(0.0)
    hits, _ = trace(layout.scene, View(center, rotation, f, cx, cy),
                    np.arange(SIZE[0], dtype=np.float64), np.arange(SIZE[1], dtype=np.float64))
    image = render_video(seed, n_frames=1, width=SIZE[0], height=SIZE[1]).frames[0].left
    return Scene(image, hits.face, hits.sid)


def wall_iou(mask: np.ndarray, scene: Scene) -> float:
    """IoU with the bare wall, ignoring the picture or mirror on it (the first click of either kind
    fills them in, as holes; the person removes them with a click of their own)."""
    care = ~scene.plane | scene.wall
    return float((mask & scene.wall & care).sum() / ((mask | scene.wall) & care).sum())


@pytest.fixture(scope="module")
def segmenter():
    return make_segmenter("classical")


@pytest.fixture(scope="module")
def scenes(segmenter) -> dict[int, tuple[Scene, Embedding]]:
    out = {}
    for seed in (1, 5, 6):
        scene = render(seed)
        out[seed] = scene, segmenter.encode(scene.image)
    return out


@pytest.mark.parametrize("seed", [1, 5, 6])
def test_a_click_on_the_back_wall_stays_off_the_boxes(segmenter, scenes, seed) -> None:
    scene, embedding = scenes[seed]
    x, y, _ = person_click(scene.wall, None)
    mask = segmenter.predict(embedding, np.array([[x, y]]), np.array([1]))[0].mask
    leaked = int((mask & ~scene.plane).sum())
    print(seed, "wall IoU", round(wall_iou(mask, scene), 3), "pixels off the wall", leaked)
    # before the fix: 10 193, 17 185 and 32 373 pixels off the wall (seed 6: a box's top and front)
    assert leaked < 0.005 * scene.wall.sum()
    assert wall_iou(mask, scene) >= 0.95


@pytest.mark.parametrize(("seed", "box"), [(1, 0), (5, 0)])
def test_a_right_click_removes_the_whole_leaked_box(segmenter, scenes, seed, box) -> None:
    """The previous mask took the wall and a box in front of it; one right-click on the box's
    front face removes all of the box, its top too, and none of the wall."""
    scene, embedding = scenes[seed]
    x, y, _ = person_click(scene.wall, None)
    front = scene.box_face(box, 2)
    nx, ny, _ = person_click(front, None)
    prev = scene.plane | scene.box(box)
    mask = segmenter.predict(embedding, np.array([[x, y], [nx, ny]]), np.array([1, 0]), prev_mask=prev)[0].mask
    left, top_left = (mask & scene.box(box)).sum(), (mask & scene.box_face(box, BOX_TOP)).sum()
    print(seed, "box pixels left", left, "of", scene.box(box).sum(), "top", top_left, "of",
          scene.box_face(box, BOX_TOP).sum())
    # before the fix: 9 895 and 11 511 pixels left, 65 % and all of the top
    assert left <= 0.01 * scene.box(box).sum()
    assert top_left <= 0.01 * scene.box_face(box, BOX_TOP).sum()
    plane_iou = (mask & scene.plane).sum() / (mask | scene.plane).sum()
    assert plane_iou >= 0.97


def test_a_negative_click_on_a_frame_keeps_the_picture_inside(segmenter, scenes) -> None:
    """The refusal takes only what the positive clicks reach after spilling out of the object: a
    right-click on a picture's frame must not take the picture's contents with it."""
    frame = render_video(3, n_frames=1, width=SIZE[0], height=SIZE[1]).frames[0]
    embedding = segmenter.encode(frame.left)
    truth = frame.regions[0].illusion
    points, labels, mask = [], [], None
    for _ in range(3):
        click = person_click(truth, mask)
        points.append(click[:2])
        labels.append(click[2])
        mask = segmenter.predict(embedding, np.array(points), np.array(labels), prev_mask=mask)[0].mask
    assert labels[1:] == [0, 0]
    assert (mask & truth).sum() / (mask | truth).sum() >= 0.85


def test_no_candidate_is_the_whole_frame(segmenter, scenes) -> None:
    """The 'holes filled' alternative filled everything outside the mask as well."""
    scene, embedding = scenes[6]
    x, y, _ = person_click(scene.wall, None)
    candidates = segmenter.predict(embedding, np.array([[x, y]]), np.array([1]))
    assert all(c.mask.mean() < 0.9 for c in candidates), [c.mask.mean() for c in candidates]
