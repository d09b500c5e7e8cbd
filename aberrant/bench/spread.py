"""``aberrant bench --workers N | --scheduler ADDR``: the bench's cells measured on a Dask cluster.

The cluster is the flythrough's (:func:`aberrant.cluster.connect`: a LocalCluster here, or a running
one). One task measures one scene's cells of one backend, exactly as a single-process run measures
them (:func:`aberrant.bench.runner.measure_scene`), so the cells, their statuses and their errors
are the same. Each task records the machine and the devices it ran on.

Timing needs the machine to itself: a task holds a cluster-wide lock named after its host while it
measures, so cells on one machine run one after another however many workers (or threads) that
machine has, while machines measure at the same time. The Embree anchor a cell is compared with is
measured by the same task, on the same machine.
"""

from __future__ import annotations

import io
import os
import socket
import sys
import time
from typing import Any, TextIO

from aberrant.bench import embree
from aberrant.bench.cells import CellRunner
from aberrant.bench.facts import machine_info
from aberrant.bench.reference import ReferenceCache
from aberrant.bench.results import document, stamp
from aberrant.bench.runner import (
    BenchConfig,
    image_errors,
    measure_scene,
    overhead_row,
    plan,
    scene_cells,
)
from aberrant.bench.scenes import SceneSpec
from aberrant.bench.sweeps import Setting
from aberrant.progress import Progress

__all__ = ["run_bench_on_cluster"]

#: What the per-machine lock's name begins with; the host name follows.
LOCK = "aberrant-bench-machine"


def _load() -> float | None:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else None


def _alone_on_this_machine() -> Any:
    """The cluster-wide lock of the host this task runs on (every bench task on it takes the same one)."""
    from distributed import Lock

    return Lock(f"{LOCK}:{socket.gethostname()}")


def measure_group(spec: SceneSpec, config: BenchConfig, settings: list[Setting]) -> dict[str, Any]:
    """On a worker: one scene's cells of one backend, with this machine to itself; rows stamped with it."""
    backends = list(dict.fromkeys(s.backend for s in settings))
    with _alone_on_this_machine():
        span = {"start": time.time()}
        load_start = _load()
        refs = ReferenceCache()
        cells = CellRunner(refs, config.repeat, image_errors=image_errors(config))
        machine = machine_info(backends, {name: cells.probe(name) for name in backends})
        embree_reason = embree.available() if config.embree else "embree: disabled"
        anchor = embree.EmbreeAnchor(config.repeat) if embree_reason is None else None
        quiet = Progress(len(scene_cells(spec, settings)), io.StringIO())
        try:
            info, scene_anchor, rows = measure_scene(spec, config, settings, cells, anchor, embree_reason, quiet)
        finally:
            if anchor is not None:
                anchor.close()
        machine["load_average"] = {"start": load_start, "end": _load()}
        span["end"] = time.time()
    return {
        "span": {"machine": machine["name"], **span},
        "machine": machine,
        "info": info,
        "anchor": scene_anchor,
        "rows": stamp(rows, machine),
        "reference_cache": {"folder": str(refs.folder), "hits": refs.hits, "misses": refs.misses},
    }


def measure_overhead_alone(name: str) -> dict[str, Any]:
    """On a worker: the engine overhead of one backend, with this machine to itself."""
    with _alone_on_this_machine():
        row = overhead_row(name)
    row["machine"] = socket.gethostname()
    return row


def _merge_machine(machines: dict[str, dict[str, Any]], machine: dict[str, Any]) -> None:
    """One entry per host: the backends its tasks saw, the lowest and highest load any of them saw."""
    known = machines.setdefault(machine["name"], {**machine, "backends": {}})
    known["backends"].update(machine["backends"])
    load, seen = known["load_average"], machine["load_average"]
    starts = [v for v in (load.get("start"), seen.get("start")) if v is not None]
    ends = [v for v in (load.get("end"), seen.get("end")) if v is not None]
    known["load_average"] = {"start": min(starts, default=None), "end": max(ends, default=None)}


def run_bench_on_cluster(
    config: BenchConfig,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    stream: TextIO | None = None,
    connect_timeout_s: float | None = None,
) -> dict[str, Any]:
    """:func:`aberrant.bench.runner.run_bench`'s document, its cells measured on a Dask cluster."""
    from aberrant.cluster import CONNECT_TIMEOUT_S, connect

    stream = stream if stream is not None else sys.stderr
    started = time.time()
    settings = plan(config)
    groups: list[tuple[SceneSpec, list[Setting]]] = []
    for spec in config.scenes:
        todo = scene_cells(spec, settings)
        for backend in config.backends:
            mine = [s for s in todo if s.backend == backend]
            if mine:
                groups.append((spec, mine))
    total = sum(len(cells) for _, cells in groups)
    timeout_s = CONNECT_TIMEOUT_S if connect_timeout_s is None else connect_timeout_s
    with connect(workers, scheduler, timeout_s) as client:
        from distributed import as_completed

        progress = Progress(total, stream)
        where = f"{workers} local workers" if scheduler is None else f"the cluster at {scheduler}"
        progress.note(f"aberrant bench: {len(config.scenes)} scenes, {total} cells in {len(groups)} tasks on {where}")
        futures = [
            client.submit(measure_group, spec, config, cells, key=f"bench-{index}-{spec.name}-{cells[0].backend}")
            for index, (spec, cells) in enumerate(groups)
        ]
        overhead_futures = (
            [client.submit(measure_overhead_alone, name, key=f"bench-overhead-{name}") for name in config.backends]
            if config.overhead
            else []
        )
        try:
            done: dict[str, dict[str, Any]] = {}
            for future in as_completed(futures, loop=client.loop):
                result = future.result()
                done[future.key] = result
                progress.step(f"{result['info']['name']} on {result['machine']['name']}", len(result["rows"]))
            overhead = [future.result() for future in overhead_futures]
        finally:
            client.cancel(futures + overhead_futures)
            progress.finish()
    scenes: dict[str, Any] = {}
    anchors: dict[str, Any] = {}
    machines: dict[str, dict[str, Any]] = {}
    rows: list[dict[str, Any]] = []
    hits = misses = 0
    for future in futures:  # the single-process run's order: scene by scene, backend by backend
        result = done[future.key]
        name = result["info"]["name"]
        scenes.setdefault(name, result["info"])
        if name not in anchors or anchors[name].get("status") != "ok":
            anchors[name] = result["anchor"]
        _merge_machine(machines, result["machine"])
        rows += result["rows"]
        hits += result["reference_cache"]["hits"]
        misses += result["reference_cache"]["misses"]
    results = document(config.as_dict(), started, settings, scenes, anchors, rows, overhead, machines)
    folder = done[futures[0].key]["reference_cache"]["folder"] if futures else ""
    results["reference_cache"] = {"folder": folder, "hits": hits, "misses": misses}
    results["spans"] = [done[future.key]["span"] for future in futures]  # when each task had its machine
    return results
