"""Dataset export and import: the native layout (``NATIVE_FORMAT.md``) and the authors' released
layout, both ways, as jobs; and a torch ``Dataset`` over a native export (``torch_dataset``, imported
on its own so that nothing else here needs torch)."""

from dataset.export.errors import LayoutError
from dataset.export.jobs import FORMATS, HANDLERS, export_job, export_params, import_job, import_params
from dataset.export.splits import parse_split_spec, split_of

__all__ = [
    "FORMATS",
    "HANDLERS",
    "LayoutError",
    "export_job",
    "export_params",
    "import_job",
    "import_params",
    "parse_split_spec",
    "split_of",
]
