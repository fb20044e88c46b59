"""The pure pieces every other package builds on: file formats (PFM, PNG disparities, images, masks and
COCO RLE, PLY), the geometry of planes, disparity, rectification and right-view synthesis (numpy and
OpenCV), atomic writes, the content-addressed file cache and how refused values are worded.

It imports nothing of the project's other packages, nor Flask, the database or torch
(``tests/test_layering.py``), so the data layer (``dataset``), the model-backed helpers (``annotation``)
and the network (``model``) all stand on it without importing each other.
"""
