"""aberrant: backends/opencl."""
