"""``aberrant bench``: every backend and setting on every scene, speed against error, in one report.

Modules: :mod:`.scenes` (what is measured), :mod:`.sweeps` (the settings),
:mod:`.cells` (one setting on one scene), :mod:`.reference` (the cached
float64 truth), :mod:`.metrics` (errors, timings, the Pareto front),
:mod:`.embree` (the outside anchor), :mod:`.overhead` (the engine's cost per
tick), :mod:`.runner` (the run), :mod:`.report` and :mod:`.plot` (the outputs).
"""

from __future__ import annotations

from aberrant.bench.runner import BenchConfig, bench_command, make_config, rerender, run_bench, write_outputs

__all__ = ["BenchConfig", "bench_command", "make_config", "rerender", "run_bench", "write_outputs"]
