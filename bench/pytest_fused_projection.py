"""Run pytest in-process with the triton backend's fused projection switched on (issue 23).

``triton_raster._FUSED_PROJECTION`` is a module flag; pytest workers would import their own copy,
so this runs without xdist. Usage: python bench/pytest_fused_projection.py [pytest args...]
"""

from __future__ import annotations

import sys

import pytest

from robogs.format.render import triton_raster

if __name__ == "__main__":
    triton_raster._FUSED_PROJECTION = True
    sys.exit(pytest.main(sys.argv[1:]))
