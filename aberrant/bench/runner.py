"""``aberrant bench``: every chosen backend and setting on every chosen scene, then the report, all at once.

The run measures (cells, Embree, engine overhead) into the results document that
:mod:`aberrant.bench.results` writes out as the report, ``results.json`` and the plots.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

from aberrant.bench import embree
from aberrant.bench.cells import CellRunner
from aberrant.bench.facts import machine_info, scene_info
from aberrant.bench.metrics import compare
from aberrant.bench.overhead import measure_overhead
from aberrant.bench.reference import ReferenceCache, render_ahead
from aberrant.bench.results import document, embree_ratio, stamp
from aberrant.bench.scenes import SceneSpec, resolve_scenes
from aberrant.bench.sweeps import IMAGE_SWEEPS, QUICK_SWEEPS, Setting, check_sweeps, settings_for
from aberrant.progress import Progress
from backends.base import BACKENDS, backend_class
from backends.samples import check_spp
from engine.camera_view import scene_camera
from engine.errors import AberrantError, BackendUnavailable
from engine.scene import Scene

DEFAULT_BACKENDS: tuple[str, ...] = ("glsl", "opencl")
FULL_SIZE, QUICK_SIZE = (800, 800), (96, 72)
FULL_REPEAT, QUICK_REPEAT = 5, 3


@dataclass
class BenchConfig:
    """A validated run: what to measure and where the report goes."""

    scenes: list[SceneSpec]
    backends: list[str]
    size: tuple[int, int]
    repeat: int
    out: Path
    quick: bool = False
    sweeps: list[str] = field(default_factory=list)
    overhead: bool = True
    embree: bool = True
    command: str = ""
    #: Worker processes that render the missing reference frames before anything is timed (1: none, lazily).
    jobs: int = 1
    #: Seconds after which the scenes not yet begun are skipped (their rows say so), so a run on borrowed
    #: time still writes its report; ``None``: no limit.
    time_limit_s: float | None = None
    #: Samples a pixel of every setting but the spp sweep's own points.
    spp: int = 1

    def as_dict(self) -> dict[str, Any]:
        return {
            "scenes": [s.name for s in self.scenes],
            "backends": self.backends,
            "size": list(self.size),
            "repeat": self.repeat,
            "quick": self.quick,
            "sweeps": self.sweeps,
            "command": self.command,
            "jobs": self.jobs,
            "time_limit_s": self.time_limit_s,
            "spp": self.spp,
        }


def _names(values: list[str] | None) -> list[str]:
    """``["a,b", "c"]`` -> ``["a", "b", "c"]``: lists may be given with commas or spaces."""
    return [n.strip() for v in values or [] for n in v.split(",") if n.strip()]


def make_config(
    *,
    scenes: list[str] | None = None,
    backends: list[str] | None = None,
    size: tuple[int, int] | None = None,
    repeat: int | None = None,
    out: str | Path = "out/bench",
    quick: bool = False,
    sweeps: list[str] | None = None,
    overhead: bool = True,
    command: str = "",
    jobs: int = 1,
    time_limit_s: float | None = None,
    spp: int = 1,
) -> BenchConfig:
    """Check every argument before anything runs.

    A bad one is an :class:`engine.errors.AberrantError` naming the choices.
    """
    specs = resolve_scenes(_names(scenes), quick)
    chosen = _names(backends) or list(DEFAULT_BACKENDS)
    for name in chosen:
        if name not in BACKENDS:
            raise AberrantError(f"unknown backend {name!r}; choose from {', '.join(BACKENDS)}")
    repeat = (QUICK_REPEAT if quick else FULL_REPEAT) if repeat is None else repeat
    if not 1 <= repeat <= 1000:
        raise AberrantError(f"--repeat must lie in [1, 1000], got {repeat}")
    if not 1 <= jobs <= 256:
        raise AberrantError(f"--jobs must lie in [1, 256], got {jobs}")
    if time_limit_s is not None and not time_limit_s > 0:
        raise AberrantError(f"--time-limit must be positive, got {time_limit_s:g}")
    sweep_names = check_sweeps(_names(sweeps)) if sweeps else list(QUICK_SWEEPS if quick else check_sweeps(["all"]))
    out_dir = Path(out)
    if out_dir.exists() and not out_dir.is_dir():
        raise AberrantError(f"--out {out_dir}: exists and is not a directory")
    return BenchConfig(
        specs,
        list(dict.fromkeys(chosen)),
        size or (QUICK_SIZE if quick else FULL_SIZE),
        repeat,
        out_dir,
        quick,
        sweep_names,
        overhead,
        True,
        command,
        jobs,
        time_limit_s,
        check_spp(spp),
    )


def asset_dir() -> Path:
    """Where generated bench meshes live (beside the BVH and reference caches)."""
    env = os.environ.get("ABERRANT_CACHE_DIR")
    return (Path(env) if env else Path.home() / ".cache" / "aberrant") / "bench-assets"


# --- the run ---------------------------------------------------------------------------------------------


def plan(config: BenchConfig) -> list[Setting]:
    out: list[Setting] = []
    for name in config.backends:
        precisions = list(backend_class(name).precisions)
        out += settings_for(name, precisions, config.sweeps, config.quick, config.spp)
    return out


def image_errors(config: BenchConfig) -> bool:
    """Whether the base cells measure their colour's error (when the spp or shadows sweep runs, or --spp is
    above 1)."""
    return any(s in config.sweeps for s in IMAGE_SWEEPS) or config.spp > 1


def scene_cells(spec: SceneSpec, settings: list[Setting]) -> list[Setting]:
    """A fixed-size scene skips the size sweep (only its own size tests what it is for); a ``base_only`` one
    every sweep (it is a point of its own), at its own samples a pixel when it fixes them."""
    if spec.base_only:
        return [replace(s, spp=spec.spp[0]) if spec.spp else s for s in settings if s.sweep == ""]
    return [s for s in settings if not (spec.size and s.sweep == "size")]


def _reference_keys(
    spec: SceneSpec, config: BenchConfig, settings: list[Setting]
) -> list[tuple[int | None, tuple[int, int]]]:
    """The (max_events, size) of every reference frame the scene's cells compare with."""
    cells = scene_cells(spec, settings)
    return sorted({(s.max_events, spec.size or s.size_for(config.size)) for s in cells}, key=str)


def render_references(config: BenchConfig, settings: list[Setting], progress: Progress) -> None:
    """Every reference frame the run will compare with, rendered in ``config.jobs`` processes, so the
    measuring that follows finds them in the disk cache (the float64 tracer is the slow part of a run)."""
    tasks = [(spec.name, _reference_keys(spec, config, settings)) for spec in config.scenes]
    progress.note(f"reference frames: {len(config.scenes)} scenes in {config.jobs} processes")
    render_ahead(tasks, asset_dir(), config.jobs, lambda name: progress.show(f"reference frames: {name}"))


def _embree_rows(
    anchor: embree.EmbreeAnchor, refs: ReferenceCache, scene: Scene, sizes: list[tuple[int, int]]
) -> dict[str, Any]:
    """Embree at every size the scene's cells use; each size's errors against the reference too."""
    camera = scene_camera(scene)
    out: dict[str, Any] = {}
    try:
        anchor.load(scene, camera)
    except Exception as e:  # the anchor is a comparison, never a reason to lose the run
        why = f"error: {type(e).__name__}: {' '.join(str(e).split())}"
        return {f"{w}x{h}": {"status": why} for w, h in sizes}
    for size in sizes:
        key = f"{size[0]}x{size[1]}"
        try:
            run = anchor.run(size)
            best = run.modes[run.best]
            rays = size[0] * size[1]
            assert run.instance is not None and run.depth is not None
            errors = compare(run.instance, run.depth, None, refs.get(scene, camera, size).aovs)
            modes = {m: {**v, "mrays_per_s": embree.mrays(v["median_ms"], rays)} for m, v in run.modes.items()}
            out[key] = {"status": "ok", "build_ms": run.build_ms, "best": run.best, "frame": best,
                        "mrays_per_s": embree.mrays(best["median_ms"], rays), "modes": modes,
                        "errors": errors.as_dict()}  # fmt: skip
        except Exception as e:  # as above
            out[key] = {"status": f"error: {type(e).__name__}: {' '.join(str(e).split())}"}
    return out


def _pair(
    anchor: embree.EmbreeAnchor | None, scene_anchor: dict[str, Any], setting: Setting, size: tuple[int, int]
) -> Callable[[], object] | None:
    """Embree's best tracer at ``size`` to interleave with a base setting's frames, or ``None``."""
    if anchor is None or scene_anchor.get("status") != "ok" or not setting.is_base or setting.backend == "reference":
        return None
    entry = scene_anchor["sizes"].get(f"{size[0]}x{size[1]}", {})
    return anchor.tracer(size, entry["best"]) if entry.get("status") == "ok" else None


def _unmeasured(
    spec: SceneSpec, config: BenchConfig, todo: list[Setting], why: str, progress: Progress
) -> tuple[dict[str, Any], dict[str, Any], list[dict[str, Any]]]:
    """The scene's facts, anchor and rows when its cells cannot be measured: each row says ``why``."""
    info = {"name": spec.name, "group": spec.group, "description": spec.description, "error": why,
            "fixed_size": list(spec.size) if spec.size else None, "entities": 0, "meshes": 0, "triangles": 0,
            "aberrations": [], "portals": 0, "euclidean": False, "max_events": 0,
            "shadows": False}  # fmt: skip
    rows = [{"scene": spec.name, "setting": s.as_dict(), "label": s.label, "family": s.family, "backend": s.backend,
             "precision": s.precision, "size": list(spec.size or s.size_for(config.size)), "status": why,
             "embree_ratio": None, "embree_note": why} for s in todo]  # fmt: skip
    progress.step(spec.name, len(todo))
    return info, {"status": why}, rows


def measure_scene(
    spec: SceneSpec,
    config: BenchConfig,
    settings: list[Setting],
    cells: CellRunner,
    anchor: embree.EmbreeAnchor | None,
    embree_reason: str | None,
    progress: Progress,
) -> tuple[dict[str, Any], dict[str, Any], list[dict[str, Any]]]:
    """Embree (on a Euclidean scene), then every cell; a scene that fails to build gives error cells."""
    todo = scene_cells(spec, settings)
    scene: Scene | None = None
    try:
        scene = spec.build(asset_dir())
        info = scene_info(spec, scene)
        camera = scene_camera(scene)
    except Exception as e:  # a broken level must not lose the other scenes' measurements
        if scene is not None:
            scene.close()
        why = f"error: the scene failed to build: {type(e).__name__}: {' '.join(str(e).split())}"
        return _unmeasured(spec, config, todo, why, progress)
    if not info["shadows"]:  # nothing to switch off: the base frame is the shadows-off frame
        skipped = [s for s in todo if s.sweep == "shadows"]
        todo = [s for s in todo if s.sweep != "shadows"]
        if skipped:
            info["skipped_sweeps"] = ["shadows"]
            progress.step(f"{spec.name}: no shadowing light", len(skipped))
    rows = []
    baseline = None
    try:
        baseline = spec.baseline(asset_dir()) if spec.baseline is not None else None
        sizes = sorted({spec.size or s.size_for(config.size) for s in todo})
        if not info["euclidean"]:
            scene_anchor: dict[str, Any] = {"status": "not applicable: the scene is not Euclidean"}
        elif anchor is None:
            scene_anchor = {"status": embree_reason}
        else:
            progress.show(f"{spec.name}: embree")
            scene_anchor = {"status": "ok", "sizes": _embree_rows(anchor, cells.references, scene, sizes)}
        for setting in todo:
            progress.show(f"{spec.name}: {setting.label}")
            size = spec.size or setting.size_for(config.size)
            plain = baseline if setting.is_base and setting.backend != "reference" else None
            row = cells.run(scene, camera, setting, size, _pair(anchor, scene_anchor, setting, size), plain,
                            spec.spp[1] if spec.spp else None, not spec.base_only)  # fmt: skip
            row["scene"] = spec.name
            embree_ratio(row, scene_anchor)
            rows.append(row)
            progress.step(f"{spec.name}: {setting.label}")
    finally:
        scene.close()
        if baseline is not None:
            baseline.close()
    return info, scene_anchor, rows


def run_bench(config: BenchConfig, stream: TextIO | None = None) -> dict[str, Any]:
    """Measure everything the config asks for; returns the results document (also what results.json holds)."""
    stream = stream if stream is not None else sys.stderr
    started = time.time()
    load_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    settings = plan(config)
    refs = ReferenceCache()
    cells = CellRunner(refs, config.repeat, image_errors=image_errors(config))
    probes = {name: cells.probe(name) for name in config.backends}
    machine = machine_info(config.backends, probes)
    embree_reason = embree.available() if config.embree else "embree: disabled"
    anchor = embree.EmbreeAnchor(config.repeat) if embree_reason is None else None
    total = sum(len(scene_cells(spec, settings)) for spec in config.scenes)
    progress = Progress(total, stream)
    if config.jobs > 1:
        render_references(config, settings, progress)
    progress.note(f"aberrant bench: {len(config.scenes)} scenes x {len(settings)} settings = {total} cells")
    rows: list[dict[str, Any]] = []
    scenes: dict[str, Any] = {}
    anchors: dict[str, Any] = {}
    try:
        for spec in config.scenes:
            if config.time_limit_s is not None and time.time() - started > config.time_limit_s:
                why = f"skipped: the run's time limit ({config.time_limit_s:g} s) was reached"
                info, scene_anchor, scene_rows = _unmeasured(spec, config, scene_cells(spec, settings), why, progress)
            else:
                info, scene_anchor, scene_rows = measure_scene(
                    spec, config, settings, cells, anchor, embree_reason, progress
                )
            scenes[spec.name], anchors[spec.name] = info, scene_anchor
            rows += stamp(scene_rows, machine)
        overhead = []
        if config.overhead:
            for name in config.backends:
                progress.show(f"engine overhead: {name}")
                overhead.append(overhead_row(name))
    finally:
        progress.finish()
        if anchor is not None:
            anchor.close()
    machine["load_average"] = {"start": load_start, "end": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}
    machines = {machine["name"]: machine}
    results = document(config.as_dict(), started, settings, scenes, anchors, rows, overhead, machines)
    results["reference_cache"] = {"folder": str(refs.folder), "hits": refs.hits, "misses": refs.misses}
    return results


def overhead_row(name: str) -> dict[str, Any]:
    """The engine-overhead measurement of one backend, or why there is none (never fatal)."""
    try:
        return measure_overhead(name, "f32" if "f32" in backend_class(name).precisions else None)
    except BackendUnavailable as e:  # the report says why
        return {"backend": name, "status": f"unsupported: {' '.join(str(e).split())}"}
    except Exception as e:  # recorded, never fatal
        return {"backend": name, "status": f"error: {type(e).__name__}: {e}"}
