"""Torch-free readers of stereo datasets, all yielding :class:`StereoSample` (pixels, NaN = invalid,
region masks): the native export, the authors' released test set, Booster, Middlebury, KITTI 2015
SceneFlow and `synth`'s rendered scenes; pinned dataset versions of the database are read by ``version.VersionReader``.

``open_reader(fmt, root, **options)`` lists a dataset's samples at once and reads each only when
indexed; a folder that is not that layout is a :class:`LayoutError` saying what was expected, a
broken file of one sample a :class:`SampleError` naming it.
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any

from dataset.export.errors import LayoutError
from dataset.readers.authors import AuthorsReader
from dataset.readers.base import Camera, ListedReader, Reader, SampleError, StereoSample, resize_sample
from dataset.readers.booster import BoosterReader
from dataset.readers.kitti import KittiReader
from dataset.readers.middlebury import MiddleburyReader
from dataset.readers.native import NativeReader
from dataset.readers.sceneflow import SceneFlowReader
from dataset.readers.synthetic import SyntheticReader

READERS: dict[str, type[ListedReader]] = {
    "native": NativeReader, "authors": AuthorsReader, "booster": BoosterReader,
    "middlebury": MiddleburyReader, "kitti": KittiReader, "sceneflow": SceneFlowReader, "synthetic": SyntheticReader,
}
READER_FORMATS = tuple(READERS)


def reader_options(fmt: str) -> list[str]:
    """The option names ``open_reader`` accepts for ``fmt``."""
    return [name for name in inspect.signature(_reader(fmt)).parameters if name != "root"]


def open_reader(fmt: str, root: Path, **options: Any) -> Reader:
    """The reader of the ``fmt`` dataset at ``root``; an option the format has not is a LayoutError naming it."""
    unknown = sorted(set(options) - set(reader_options(fmt)))
    if unknown:
        raise LayoutError(f"format {fmt!r} has no option {', '.join(map(repr, unknown))}; "
                          f"it takes {', '.join(reader_options(fmt)) or 'none'}")
    return _reader(fmt)(Path(root), **options)


def _reader(fmt: str) -> type[ListedReader]:
    if fmt not in READERS:
        raise LayoutError(f"unknown dataset format {fmt!r}; use one of {', '.join(READER_FORMATS)}")
    return READERS[fmt]


__all__ = ["READER_FORMATS", "Camera", "LayoutError", "Reader", "SampleError", "StereoSample", "open_reader",
           "reader_options", "resize_sample"]
