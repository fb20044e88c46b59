"""The sample preview: point clouds, 2D renders, the .viser scene export, and its login-protected routes."""

from __future__ import annotations

import cv2
import msgspec
import numpy as np
import pytest
import zstandard

from dataset.db import transaction
from dataset.preview import images, qa
from dataset.preview.cloud import HIGHLIGHT_RGB, VirtualCamera, disparity_cloud, grid_stride
from dataset.preview.scene import export_scene
from dataset.samples import store_outputs
from dataset.tables import Frame, FrameState, Sample, SourceKind, Video

H, W = 48, 64


def _scene() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A textured image, a tilted-plane disparity (px) and an illusion mask in its middle."""
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    v, u = np.mgrid[0:H, 0:W]
    disparity = (8.0 + 0.05 * u + 0.02 * v).astype(np.float32)
    mask = np.zeros((H, W), bool)
    mask[16:32, 20:44] = True
    return image, disparity, mask


def _decode(scene: bytes) -> dict:  # type: ignore[type-arg]
    """The msgpack part of a .viser file: 8-byte size, zstd of (8-byte length, msgpack, buffers)."""
    inner = zstandard.ZstdDecompressor().decompress(scene[8:], max_output_size=int.from_bytes(scene[:8], "little"))
    length = int.from_bytes(inner[:8], "little")
    return msgspec.msgpack.decode(inner[8 : 8 + length])


def _camera(messages: list[dict]) -> list[dict]:  # type: ignore[type-arg]
    return [m for m in messages if m["type"].startswith("SetCamera")]


# ---- point clouds -----------------------------------------------------------------------------


def test_cloud_shapes_colours_and_the_virtual_camera() -> None:
    image, disparity, _ = _scene()
    cloud = disparity_cloud(image, disparity, baseline=0.1)
    assert cloud.points.shape == (H * W, 3) and cloud.points.dtype == np.float32
    assert cloud.colors.shape == (H * W, 3) and cloud.colors.dtype == np.uint8
    np.testing.assert_array_equal(cloud.colors, image.reshape(-1, 3))
    # depth = fx·B/d with fx = image width
    np.testing.assert_allclose(cloud.points[:, 2], W * 0.1 / disparity.reshape(-1), rtol=1e-5)
    camera = VirtualCamera(W, H)
    assert camera.focal == W and camera.fov_y == pytest.approx(2 * np.arctan(H / (2 * W)))
    assert cloud.median_depth == pytest.approx(np.median(cloud.points[:, 2]))


def test_a_plane_in_disparity_stays_a_plane_in_3d() -> None:
    image, disparity, _ = _scene()
    points = disparity_cloud(image, disparity).points.astype(np.float64)
    centred = points - points.mean(axis=0)
    singular = np.linalg.svd(centred, compute_uv=False)
    assert singular[2] < 1e-4 * singular[0]


def test_subsampling_keeps_a_regular_grid_under_the_budget() -> None:
    image, disparity, _ = _scene()
    for budget in (1, 7, 100, 768, 3071, H * W):
        stride = grid_stride(H, W, budget)
        cloud = disparity_cloud(image, disparity, max_points=budget)
        assert len(cloud.points) <= budget
        assert len(cloud.points) == -(-H // stride) * -(-W // stride)
        assert stride == 1 or -(-H // (stride - 1)) * -(-W // (stride - 1)) > budget  # the finest that fits
    coarse = disparity_cloud(image, disparity, max_points=768)
    np.testing.assert_array_equal(coarse.colors, image[::2, ::2].reshape(-1, 3))
    assert coarse.spacing == pytest.approx(2 * disparity_cloud(image, disparity).spacing, rel=0.05)
    with pytest.raises(ValueError):
        grid_stride(H, W, 0)


def test_invalid_and_far_disparities_are_dropped() -> None:
    image, disparity, _ = _scene()
    disparity[0, :] = np.nan
    disparity[1, :] = 0
    disparity[2, :] = -3
    disparity[3, :] = 1e-4  # the sky of a relative disparity: kilometres away
    assert len(disparity_cloud(image, disparity).points) == (H - 4) * W
    assert len(disparity_cloud(image, np.full((H, W), np.nan, np.float32)).points) == 0


def test_the_illusion_region_is_tinted_and_nothing_else() -> None:
    image, disparity, mask = _scene()
    plain = disparity_cloud(image, disparity)
    tinted = disparity_cloud(image, disparity, highlight=mask)
    inside = mask.reshape(-1)
    np.testing.assert_array_equal(tinted.colors[~inside], plain.colors[~inside])
    target = np.array(HIGHLIGHT_RGB, float)
    assert (np.abs(tinted.colors[inside] - target).sum(axis=1) < np.abs(plain.colors[inside] - target).sum(axis=1)).all()
    np.testing.assert_array_equal(tinted.points, plain.points)
    with pytest.raises(ValueError, match="highlight"):
        disparity_cloud(image, disparity, highlight=mask[:-1])


# ---- 2D renders -------------------------------------------------------------------------------


def test_colorize_ends_no_value_and_colour_bar_agree() -> None:
    values = np.array([[2.0, 6.0, np.nan]], np.float32)
    rgb = images.colorize(values, 2.0, 6.0)
    stops = images.colorbar_stops(11)
    assert f"#{rgb[0, 0, 0]:02x}{rgb[0, 0, 1]:02x}{rgb[0, 0, 2]:02x}" == stops[0]
    assert f"#{rgb[0, 1, 0]:02x}{rgb[0, 1, 1]:02x}{rgb[0, 1, 2]:02x}" == stops[-1]
    assert tuple(rgb[0, 2]) == images.NO_VALUE_RGB
    assert images.value_range(values, np.array([[1.0, np.inf]])) == (1.0, 6.0)
    assert images.value_range(np.full((2, 2), np.nan)) == (0.0, 1.0)


def test_error_maps_run_dark_to_bright_and_mark_missing_truth() -> None:
    err = np.array([[0.0, 1.5, 3.0, 30.0, np.nan]], np.float32)
    rgb = images.colorize_error(err, 3.0)
    assert rgb.shape == (1, 5, 3) and rgb.dtype == np.uint8
    brightness = rgb[0, :4].astype(int).sum(axis=1)
    assert brightness[0] < 10 and brightness[0] < brightness[1] < brightness[2] == brightness[3]
    assert tuple(rgb[0, 4]) == images.ERROR_NO_VALUE_RGB
    np.testing.assert_array_equal(images.colorize_error(-err, 3.0), rgb)  # signed errors by magnitude
    with pytest.raises(ValueError, match="max_px"):
        images.colorize_error(err, 0.0)


def test_colour_bar_is_appended_with_the_map_high_at_the_top() -> None:
    disparity = np.tile(np.linspace(0, 10, 64, dtype=np.float32), (48, 1))
    rgb = images.colorize(disparity, 0.0, 10.0)
    figure = images.add_colorbar(rgb, 0.0, 10.0)
    assert figure.shape[0] == 48 and figure.shape[1] > 64 and figure.dtype == np.uint8
    np.testing.assert_array_equal(figure[:, :64], rgb)
    bar = figure[:, 64 + 4 + 1]  # one column inside the bar
    assert np.abs(bar[0].astype(int) - rgb[0, -1]).sum() <= 12  # top = hi
    assert np.abs(bar[-1].astype(int) - rgb[0, 0]).sum() <= 12  # bottom = lo
    error_bar = images.add_colorbar(images.colorize_error(disparity, 10.0), 0.0, 10.0, error=True)[:, 64 + 4 + 1]
    assert error_bar[0].astype(int).sum() > error_bar[-1].astype(int).sum()


def test_anaglyph_holes_and_outlines() -> None:
    left = np.full((H, W, 3), 10, np.uint8)
    right = np.full((H, W, 3), 200, np.uint8)
    red_cyan = images.anaglyph(left, right)
    assert tuple(red_cyan[0, 0]) == (10, 200, 200)
    holes = np.zeros((H, W), bool)
    holes[:, :5] = True
    shown = images.blend(right, holes, images.HOLE_RGB, 1.0)
    assert tuple(shown[0, 0]) == images.HOLE_RGB and tuple(shown[0, 10]) == (200, 200, 200)
    _, _, mask = _scene()
    outlined = images.outline(left, {"illusion_00": mask, "support_00": np.zeros_like(mask)})
    assert tuple(outlined[16, 30]) == images.ILLUSION_RGB  # on the region's edge
    assert tuple(outlined[24, 30]) == (10, 10, 10)  # inside it, untouched
    assert images.shrink(np.zeros((100, 400, 3), np.uint8), 200).shape == (50, 200, 3)
    png = images.encode_png(red_cyan)
    assert cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR).shape == (H, W, 3)


def test_qa_rows_mark_what_the_flags_name() -> None:
    figures = {"scale": 4.66, "hole_fraction": 0.25, "stereo_epe": None, "stereo_bad2": 0.035, "cpu_s": 0.14,
               "flags": ["holes 25% > 20%", "pair 2 inlier ratio 0.31 < 0.5"],
               "pairs": [{"pair": 0, "status": "rectified", "inlier_ratio": 1.0, "plane": [0.1, 0.2, 0.97, -16.4]},
                         {"pair": 1, "status": "rectified", "inlier_ratio": 0.31}]}
    rows = {row.label: row for row in qa.summary_rows(figures)}
    assert rows["Holes in the right view"].flagged and rows["Holes in the right view"].value == "25.0 %"
    assert not rows["SGBM end-point error"].flagged and rows["SGBM end-point error"].value == "–"
    assert rows["Disparity scale"].value == "4.66 px/unit"
    pairs = qa.pair_rows(figures)
    assert [p.flagged for p in pairs] == [False, True]
    assert [p.pair for p in pairs] == [1, 2]  # for people, from 1: the stored ids start at 0 here
    assert pairs[0].plane == "0.1, 0.2, 0.97, -16.4" and pairs[1].inlier_ratio == "31.0 %"


# ---- scene export -----------------------------------------------------------------------------


def test_scene_export_is_deterministic_and_holds_both_clouds_and_the_frustum() -> None:
    image, disparity, mask = _scene()
    clouds = {"after_rectification": disparity_cloud(image, disparity, highlight=mask),
              "before_rectification": disparity_cloud(image, disparity * 0.8, highlight=mask)}
    first = export_scene(clouds, "after_rectification", VirtualCamera(W, H))
    assert len(first) > 1000
    assert export_scene(clouds, "after_rectification", VirtualCamera(W, H)) == first
    messages = [message for _, message in _decode(first)["messages"]]
    visible = {m["name"]: m["visible"] for m in messages if m["type"] == "SetSceneNodeVisibilityMessage"}
    assert visible["/after_rectification"] and visible["/camera"]
    assert not visible["/before_rectification"]  # one switch away in the client's scene tree
    assert {m["type"] for m in messages if m.get("name") == "/camera"} >= {"CameraFrustumMessage"}
    other = [m for _, m in _decode(export_scene(clouds, "before_rectification", VirtualCamera(W, H)))["messages"]]
    assert other != messages
    assert _camera(other) == _camera(messages)  # switching stage keeps the viewpoint
    with pytest.raises(ValueError, match="visible"):
        export_scene(clouds, "sideways", VirtualCamera(W, H))


# ---- routes -----------------------------------------------------------------------------------


@pytest.fixture
def sample_ids(runtime):  # type: ignore[no-untyped-def]
    """(sample id, frame id with that sample, frame id without one), outputs in the media store."""
    image, disparity, mask = _scene()
    holes = np.zeros((H, W), bool)
    holes[:, -4:] = True
    files = store_outputs(runtime.media, {
        "left": image, "right": np.roll(image, -3, axis=1), "disparity": disparity * 2,
        "disparity_rect": disparity, "disparity_mono": disparity * 0.7, "holes": holes,
        "masks": {"illusion_00": mask, "support_00": ~mask},
    })
    with transaction(runtime.sessions) as s:
        video = Video(name="v", source_kind=SourceKind.web, content_sha256="a" * 64)
        s.add(video)
        s.flush()
        frames = [Frame(video_id=video.id, index=i, time_s=float(i), width=W, height=H, content_sha256=f"{i:064d}",
                        media_key=files["left"], state=FrameState.generated) for i in range(2)]
        s.add_all(frames)
        s.flush()
        sample = Sample(frame_id=frames[0].id, annotation_version=1, files=files, params={"scale": 2.0},
                        provenance={"depth_backend": "synthetic"},
                        qa={"pairs": [], "scale": 2.0, "hole_fraction": float(holes.mean()), "stereo_epe": 0.5,
                            "flags": []})
        s.add(sample)
        s.flush()
        return sample.id, frames[0].id, frames[1].id


def _as(tokens: dict[str, str], role: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {tokens[role]}"}


def test_preview_routes_refuse_anonymous_callers(client, sample_ids) -> None:  # type: ignore[no-untyped-def]
    sample_id, frame_id, _ = sample_ids
    for path in (f"/samples/{sample_id}/scene.viser", f"/samples/{sample_id}/scene.viser?stage=before",
                 f"/samples/{sample_id}/preview", f"/samples/{sample_id}/views/anaglyph.png",
                 "/viser/index.html", f"/frames/{frame_id}/preview", "/samples", f"/samples/{sample_id}"):
        response = client.get(path)
        assert response.status_code == 302 and "/login?next=" in response.location, path


def test_scene_and_client_are_served_to_logged_in_users(client, tokens, sample_ids) -> None:  # type: ignore[no-untyped-def]
    sample_id, _, _ = sample_ids
    headers = _as(tokens, "annotator")
    after = client.get(f"/samples/{sample_id}/scene.viser", headers=headers)
    assert after.status_code == 200 and after.mimetype == "application/octet-stream"
    assert after.headers["Content-Length"] == str(len(after.data))  # the viser client sizes its download by it
    names = {m["name"] for _, m in _decode(after.data)["messages"] if "name" in m}
    assert {"/after_rectification", "/before_rectification", "/camera"} <= names
    again = client.get(f"/samples/{sample_id}/scene.viser?stage=after", headers=headers)
    assert again.data == after.data  # from the cache
    before = client.get(f"/samples/{sample_id}/scene.viser?stage=before", headers=headers)
    assert before.status_code == 200 and before.data != after.data
    assert client.get(f"/samples/{sample_id}/scene.viser?stage=sideways", headers=headers).status_code == 404
    assert client.get("/samples/999/scene.viser", headers=headers).status_code == 404
    viewer = client.get("/viser/index.html", headers=headers)
    assert viewer.status_code == 200 and viewer.mimetype == "text/html" and b"Viser" in viewer.data


def test_2d_views_render_as_png(client, tokens, sample_ids) -> None:  # type: ignore[no-untyped-def]
    sample_id, _, _ = sample_ids
    headers = _as(tokens, "annotator")
    for view in ("disparity_before", "disparity_after", "masks", "right_holes", "anaglyph"):
        response = client.get(f"/samples/{sample_id}/views/{view}.png", headers=headers)
        assert response.status_code == 200 and response.mimetype == "image/png", view
        image = cv2.imdecode(np.frombuffer(response.data, np.uint8), cv2.IMREAD_COLOR)
        assert image.shape == (H, W, 3), view
    shown = client.get(f"/samples/{sample_id}/views/right_holes.png?size=thumb", headers=headers)
    right = cv2.cvtColor(cv2.imdecode(np.frombuffer(shown.data, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    source = np.roll(_scene()[0], -3, axis=1)
    expected = images.blend(source, np.ones((H, W), bool), images.HOLE_RGB, images.HOLE_ALPHA)
    np.testing.assert_array_equal(right[:, -4:], expected[:, -4:])  # the holes, in lime
    np.testing.assert_array_equal(right[:, :-4], source[:, :-4])
    assert client.get(f"/samples/{sample_id}/views/sideways.png", headers=headers).status_code == 404


def test_sample_page_shows_the_colour_bar_and_review_buttons_by_role(client, tokens, sample_ids) -> None:  # type: ignore[no-untyped-def]
    sample_id, _, _ = sample_ids
    page = client.get(f"/samples/{sample_id}", headers=_as(tokens, "annotator")).get_data(as_text=True)
    # after = 2·d, before = scale 2 · 0.7·d: one range over both, in px
    _, disparity, _ = _scene()
    assert f'data-end="lo">{1.4 * disparity.min():.1f}<' in page and f'data-end="hi">{2 * disparity.max():.1f}<' in page
    assert 'id="accept"' not in page
    assert 'id="accept"' in client.get(f"/samples/{sample_id}", headers=_as(tokens, "curator")).get_data(as_text=True)
    preview = client.get(f"/samples/{sample_id}/preview", headers=_as(tokens, "annotator")).get_data(as_text=True)
    assert 'data-open-viewer="true"' in preview


def test_frame_preview_redirects_to_the_newest_sample_or_explains(client, tokens, sample_ids) -> None:  # type: ignore[no-untyped-def]
    sample_id, frame_id, bare_frame_id = sample_ids
    headers = _as(tokens, "annotator")
    response = client.get(f"/frames/{frame_id}/preview", headers=headers)
    assert response.status_code == 302 and response.location.endswith(f"/samples/{sample_id}/preview")
    missing = client.get(f"/frames/{bare_frame_id}/preview", headers=headers)
    assert missing.status_code == 404 and "no generated sample yet" in missing.get_data(as_text=True)
    assert client.get("/frames/999/preview", headers=headers).status_code == 404


def test_the_render_cache_keeps_within_its_budget(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import os

    from dataset.preview.cache import RenderCache

    cache = RenderCache(tmp_path / "preview", budget_bytes=2500)
    first = cache.get_or_make({"sample": 1}, "png", lambda: b"a" * 1000)
    os.utime(first, (1, 1))  # long unused
    second = cache.get_or_make({"sample": 2}, "png", lambda: b"b" * 1000)
    third = cache.get_or_make({"sample": 3}, "png", lambda: b"c" * 1000)
    assert not first.exists() and second.exists() and third.exists() and cache.usage() == 2000
    assert cache.get_or_make({"sample": 2}, "png", lambda: b"never made") == second
    assert second.read_bytes() == b"b" * 1000
