"""robogs fixtures."""
