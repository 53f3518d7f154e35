"""Deprecated: ``reference_impl.physics`` is ``robogs.physics`` and ``reference_impl.reconstruct``
is ``robogs.reconstruct`` (removed in robogs 0.3)."""

from robogs._compat import install

install(__name__)
