"""Model-backed hole filling for synthesized right views.

Backends: ``lama`` (a TorchScript LaMa export such as ``big-lama.pt``, local file). The
classical methods (OpenCV Telea / Navier–Stokes) are in :mod:`core.geometry.inpaint`, which
takes a backend's ``inpaint`` as its hole filler.
"""

from annotation.inpaint.base import Inpainter, InpainterError
from annotation.inpaint.registry import INPAINT_BACKENDS, make_inpainter

__all__ = ["INPAINT_BACKENDS", "Inpainter", "InpainterError", "make_inpainter"]
