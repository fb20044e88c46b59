"""Previews of a generated sample: a 3D viser scene (point clouds before/after rectification) and
2D renders (colourised disparities, holes, anaglyph, mask outlines), cached on disk.

``cloud`` and ``images`` are pure numpy/OpenCV; ``scene`` turns clouds into a ``.viser`` file;
``sample_preview`` loads a sample's outputs and caches what the others make.
"""
