"""Data files for the demos (meshes); ``make_knot`` regenerates ``knot.obj``."""
