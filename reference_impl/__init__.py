"""robogs reference_impl."""
