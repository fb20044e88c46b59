"""File formats: PFM, 16-bit PNG disparity (KITTI ×256, authors' ×16 + scale CSV), lossless
PNG masks, PLY point clouds, and suffix-dispatched float maps."""

from dataset.formats.disparity_png import (
    AUTHORS_FACTOR,
    KITTI_FACTOR,
    read_authors_disparity,
    read_kitti_disparity,
    read_scale_factors,
    write_authors_disparity,
    write_kitti_disparity,
    write_scale_factors,
)
from dataset.formats.errors import FormatError
from dataset.formats.float_maps import MAP_SUFFIXES, read_map, write_map
from dataset.formats.images import read_image, read_rgb, write_png, write_rgb
from dataset.formats.masks import read_mask, write_mask
from dataset.formats.pfm import decode_pfm, encode_pfm, read_pfm, write_pfm
from dataset.formats.ply import disparity_point_cloud, read_ply, write_ply

__all__ = [
    "AUTHORS_FACTOR",
    "KITTI_FACTOR",
    "MAP_SUFFIXES",
    "FormatError",
    "decode_pfm",
    "disparity_point_cloud",
    "encode_pfm",
    "read_authors_disparity",
    "read_image",
    "read_kitti_disparity",
    "read_map",
    "read_mask",
    "read_pfm",
    "read_ply",
    "read_rgb",
    "read_scale_factors",
    "write_authors_disparity",
    "write_kitti_disparity",
    "write_map",
    "write_mask",
    "write_pfm",
    "write_ply",
    "write_png",
    "write_rgb",
    "write_scale_factors",
]
