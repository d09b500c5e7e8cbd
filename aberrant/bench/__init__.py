"""``aberrant bench``: every backend and setting on every scene, speed against error, in one report.

Modules: :mod:`.scenes` (what is measured), :mod:`.sweeps` (the settings),
:mod:`.cells` (one setting on one scene), :mod:`.reference` (the cached
float64 truth), :mod:`.metrics` (errors, timings, the Pareto front),
:mod:`.embree` (the outside anchor), :mod:`.overhead` (the engine's cost per
tick), :mod:`.runner` (the run), :mod:`.report` and :mod:`.plot` (the outputs).
"""

from __future__ import annotations

from aberrant.bench.command import bench_command
from aberrant.bench.results import rerender, write_outputs
from aberrant.bench.runner import BenchConfig, make_config, run_bench

# The modules are listed too, so that the API reference documents them.
__all__ = [
    "BenchConfig",
    "bench_command",
    "cells",
    "embree",
    "make_config",
    "metrics",
    "overhead",
    "plot",
    "reference",
    "report",
    "rerender",
    "run_bench",
    "runner",
    "scenes",
    "sweeps",
    "write_outputs",
]
