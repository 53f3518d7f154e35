"""robogs converters."""
