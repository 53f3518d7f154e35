"""Deprecated alias of ``robogs.format`` (removed in robogs 0.3)."""

import sys

from robogs._compat import install

sys.modules[__name__] = install(__name__)
