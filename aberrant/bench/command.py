"""``aberrant bench``'s run: measured here or on a Dask cluster, then written and reported.

Above both ways of measuring (:mod:`aberrant.bench.runner` here, :mod:`aberrant.bench.spread` on a
cluster), so neither needs the other.
"""

from __future__ import annotations

from typing import TextIO

from aberrant.bench.results import write_outputs
from aberrant.bench.runner import BenchConfig, run_bench
from aberrant.bench.spread import run_bench_on_cluster
from aberrant.progress import clock


def bench_command(
    config: BenchConfig, stream: TextIO | None = None, *, workers: int | None = None, scheduler: str | None = None
) -> int:
    """Run (here, or on a Dask cluster given ``workers`` or ``scheduler``), write, and say where the report is."""
    if workers is None and scheduler is None:
        results = run_bench(config, stream)
    else:
        results = run_bench_on_cluster(config, workers=workers, scheduler=scheduler, stream=stream)
    paths = write_outputs(results, config.out)
    for path in paths:
        print(f"wrote {path}")
    print(f"bench: {len(results['rows'])} cells in {clock(results['duration_s'])}")
    return 0
