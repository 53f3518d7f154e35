"""Ingest converters: one module per source format (bags, MCAP, video, nerfstudio, COLMAP).

Importing a module registers its converter in :mod:`robogs.convert.registry`; use
:func:`robogs.convert.ingest.convert.convert_path` to run a conversion.
"""

from .context import ConvertOptions, IngestContext
from .convert import convert_path

__all__ = ["ConvertOptions", "IngestContext", "convert_path"]
