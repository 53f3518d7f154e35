"""Reference reconstructor (work in progress)."""
