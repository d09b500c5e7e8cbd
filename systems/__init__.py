"""aberrant: systems."""
