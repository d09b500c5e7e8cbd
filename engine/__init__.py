"""aberrant: engine."""
