"""aberrant: backends."""
