"""File formats: PFM, 16-bit PNG disparity (KITTI ×256, authors' ×16 + scale CSV), lossless
PNG masks, COCO RLE masks, PLY point clouds, and suffix-dispatched float maps."""

from core.formats.disparity_png import (
    AUTHORS_FACTOR,
    KITTI_FACTOR,
    decode_authors_disparity,
    decode_kitti_disparity,
    read_authors_disparity,
    read_kitti_disparity,
    read_scale_factors,
    write_authors_disparity,
    write_kitti_disparity,
    write_scale_factors,
)
from core.formats.errors import FormatError
from core.formats.float_maps import MAP_SUFFIXES, PNG_ENCODINGS, PngEncoding, decode_npy, read_map, write_map
from core.formats.images import decode_image, read_bytes, read_image, read_rgb, write_png, write_rgb
from core.formats.masks import read_mask, write_mask
from core.formats.pfm import decode_pfm, encode_pfm, read_pfm, write_pfm
from core.formats.ply import disparity_point_cloud, read_ply, write_ply
from core.formats.rle import mask_to_rle, rle_to_mask

__all__ = [
    "AUTHORS_FACTOR",
    "KITTI_FACTOR",
    "MAP_SUFFIXES",
    "PNG_ENCODINGS",
    "FormatError",
    "PngEncoding",
    "decode_authors_disparity",
    "decode_image",
    "decode_kitti_disparity",
    "decode_npy",
    "decode_pfm",
    "disparity_point_cloud",
    "encode_pfm",
    "mask_to_rle",
    "read_authors_disparity",
    "read_bytes",
    "read_image",
    "read_kitti_disparity",
    "read_map",
    "read_mask",
    "read_pfm",
    "read_ply",
    "read_rgb",
    "read_scale_factors",
    "rle_to_mask",
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
