"""aberrant: ray-traced scenes in deformed space, the application and its public Python API."""
