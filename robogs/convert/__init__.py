"""robogs converters: ingest of bags, MCAP, videos and captures; exports to other formats.

Ingest converters are kept in a registry keyed by source format; see
:mod:`robogs.convert.registry` (``register_converter``, ``available_converters``, entry-point group
``robogs.converters``) and :func:`robogs.convert.ingest.convert_path`.
"""

from .registry import (
    Converter,
    ConverterOptions,
    available_converters,
    detect_format,
    get_converter,
    register_converter,
)

__all__ = [
    "Converter",
    "ConverterOptions",
    "available_converters",
    "detect_format",
    "get_converter",
    "register_converter",
]
