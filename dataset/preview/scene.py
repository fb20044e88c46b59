"""A sample's 3D scene as a ``.viser`` recording, for viser's prebuilt client to play back.

viser builds scenes through a ``ViserServer``; here one lives for a single export, bound to an
ephemeral loopback port that nobody is told about, and is stopped before the bytes are returned.
The browser never talks to it: Flask serves the recording and viser's static client.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Iterator, Mapping

from dataset.preview.cloud import PointCloud, VirtualCamera

# Bump when the scene's content changes, so cached recordings are rebuilt.
SCENE_VERSION = 1
# OpenCV camera frame (X right, Y down, Z forward) → viser's Z-up world: a -90° turn about X.
CAMERA_TO_WORLD = (math.sqrt(0.5), -math.sqrt(0.5), 0.0, 0.0)
FRUSTUM_RGB = (79, 70, 229)
POINT_SIZE_FACTOR = 1.3  # a little larger than the grid spacing, so a surface reads as closed

# One export at a time: each starts a server thread and holds its clouds in memory twice
# (arrays and encoded messages), and the console switch below is process-wide.
_export_lock = threading.Lock()


@contextlib.contextmanager
def _quiet_viser() -> Iterator[None]:
    """viser prints a banner with its (here meaningless) URL on start and a line on stop."""
    import rich

    console = rich.get_console()
    was = console.quiet
    console.quiet = True
    try:
        yield
    finally:
        console.quiet = was


def export_scene(clouds: Mapping[str, PointCloud], visible: str, camera: VirtualCamera) -> bytes:
    """Serialize a scene of named point clouds (only ``visible`` shown at first; the others can be
    switched on in the client's scene tree) and the camera's frustum into ``.viser`` bytes. The view
    is framed on the first cloud, so scenes that differ only in ``visible`` start from one viewpoint.
    Same inputs, same bytes."""
    if visible not in clouds:
        raise ValueError(f"visible must be one of {sorted(clouds)}, got {visible!r}")
    import viser

    depth = next(iter(clouds.values())).median_depth
    with _export_lock, _quiet_viser():
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
        try:
            scene = server.scene
            # Top-level nodes, each turned into the world: one click apiece in the client's scene tree.
            for name, cloud in clouds.items():
                scene.add_point_cloud(f"/{name}", points=cloud.points, colors=cloud.colors, wxyz=CAMERA_TO_WORLD,
                                      point_size=cloud.spacing * POINT_SIZE_FACTOR, point_shading="flat",
                                      visible=name == visible)
            scene.add_camera_frustum("/camera", fov=camera.fov_y, aspect=camera.aspect, scale=0.05 * depth,
                                     thickness=0.002 * depth, color=FRUSTUM_RGB, wxyz=CAMERA_TO_WORLD)
            # From behind, above and to the left of the camera: relief and flatness show at a slant.
            server.initial_camera.position = (-0.3 * depth, -0.25 * depth, 0.25 * depth)
            server.initial_camera.look_at = (0.0, depth, 0.0)
            server.initial_camera.up = (0.0, 0.0, 1.0)
            server.initial_camera.fov = camera.fov_y * 1.6
            return server.get_scene_serializer().serialize()
        finally:
            server.stop()
