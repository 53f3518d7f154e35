"""The ``robogs`` command line."""
