"""aberrant: demos."""
