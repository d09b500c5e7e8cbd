"""The ``render`` command: one frame of a level (a PNG, and its AOVs as an archive), or with ``--path`` a
flythrough, here or on a Dask cluster. Outputs are written only after the render succeeded, each through a
temporary file and a rename."""

from __future__ import annotations

import argparse
import io
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from aberrant.arguments import UsageError, check_cluster_args, check_target, parse_size, parse_spp
from aberrant.running import check_frame_memory, with_fallback

if TYPE_CHECKING:
    from aberrant.levels import Level
    from backends.base import Backend, Frame

#: Keys of the ``--aovs`` archive: the AOVs besides colour (which is the PNG).
NPZ_AOVS = ("depth", "perceived", "instance", "events")


def _png_bytes(color: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(color), mode="RGBA" if color.shape[2] == 4 else "RGB").save(buffer, "PNG")
    return buffer.getvalue()


def _npz_bytes(frame: Frame) -> bytes:
    buffer = io.BytesIO()
    # mypy cannot tell that the unpacked AOV names never include savez's allow_pickle keyword.
    np.savez_compressed(buffer, **{name: frame.aov(name) for name in NPZ_AOVS})  # type: ignore[arg-type]
    return buffer.getvalue()


def cmd_render(args: argparse.Namespace) -> int:
    from aberrant.levels import open_level
    from backends.base import AOVS
    from engine.atomic_files import write_atomically
    from systems.app import render_once

    if args.path:
        return cmd_render_path(args)
    if args.frames is not None or args.fps is not None or args.duration is not None:
        raise UsageError("--frames, --fps and --duration render a flythrough; add --path")
    if args.workers is not None or args.scheduler is not None:
        raise UsageError("--workers and --scheduler spread a flythrough's frames; add --path")
    width, height = parse_size(args.size)
    spp = parse_spp(args.spp)
    out = Path(args.out or "frame.png")
    check_target("--out", out)
    npz = Path(args.aovs) if args.aovs else None
    if npz is not None:
        check_target("--aovs", npz)
        if os.path.abspath(npz) == os.path.abspath(out):
            raise UsageError("--out and --aovs name the same file")
    scene = open_level(args.scene).scene
    aovs = AOVS if npz is not None else ("color",)

    def render(backend: Backend) -> tuple[Frame, float]:
        check_frame_memory(backend, (width, height), aovs, "leave out --aovs" if npz is not None else "")
        start = time.perf_counter()
        frame = render_once(scene, backend, (width, height), aovs, spp=spp)
        return frame, (time.perf_counter() - start) * 1e3

    try:
        (frame, elapsed_ms), backend_name = with_fallback(args, render)
    finally:
        scene.close()
    outputs = {out: _png_bytes(frame.aov("color"))}
    if npz is not None:
        outputs[npz] = _npz_bytes(frame)
    write_atomically(outputs)
    for path in outputs:
        print(f"wrote {path}")
    render_ms = frame.timings_ms.get("render")
    detail = f" (render {render_ms:.1f} ms)" if render_ms is not None else ""
    samples = f", {spp} samples a pixel" if spp > 1 else ""
    print(f"{width}x{height}{samples} with the {backend_name} backend in {elapsed_ms:.1f} ms{detail}")
    return 0


def cmd_render_path(args: argparse.Namespace) -> int:
    """``render --path``: a flythrough walked by the real systems (aberrant/flythrough.py)."""
    from aberrant.flythrough import check_output, path_for, plan_frames, render_flythrough
    from aberrant.levels import open_level

    if args.aovs:
        raise UsageError("--aovs writes one frame's AOVs; it cannot be combined with --path")
    width, height = parse_size(args.size)
    spp = parse_spp(args.spp)
    out = Path(args.out or "flythrough.gif")
    check_output(out)
    check_cluster_args(args)
    level = open_level(args.scene)
    scene = level.scene
    if args.workers is not None or args.scheduler is not None:
        return _render_path_on_cluster(args, level, (width, height), out, spp)

    def render(backend: Backend) -> float:
        check_frame_memory(backend, (width, height), ("color",), "")
        start = time.perf_counter()
        render_flythrough(scene, backend, path, frames, (width, height), out, fps=fps, spp=spp)
        return time.perf_counter() - start

    try:
        path = path_for(level)
        frames, fps = plan_frames(path, fps=args.fps, frames=args.frames, duration=args.duration)
        print(f"path: {path.duration:.1f} s, {frames} frames at {fps:g} fps")
        elapsed, backend_name = with_fallback(args, render)
    finally:
        scene.close()
    print(f"wrote {out}")
    print(f"{frames} frames of {width}x{height} with the {backend_name} backend in {elapsed:.1f} s")
    return 0


def _render_path_on_cluster(args: argparse.Namespace, level: Level, size: tuple[int, int], out: Path, spp: int) -> int:
    """``render --path --workers N | --scheduler ADDR``: the frames rendered on a Dask cluster (aberrant/cluster.py)."""
    from aberrant.cluster import render_distributed
    from aberrant.flythrough import path_for, plan_frames
    from backends.base import default_backend_name

    try:
        path = path_for(level)
        frames, fps = plan_frames(path, fps=args.fps, frames=args.frames, duration=args.duration)
        where = f"{args.workers} local workers" if args.scheduler is None else f"the cluster at {args.scheduler}"
        print(f"path: {path.duration:.1f} s, {frames} frames at {fps:g} fps, on {where}")
        start = time.perf_counter()
        backend_name = render_distributed(
            level.scene, path, frames, size, out, backend=args.backend or default_backend_name(),
            precision=args.precision, workers=args.workers, scheduler=args.scheduler, fps=fps, spp=spp,
        )  # fmt: skip
        elapsed = time.perf_counter() - start
    finally:
        level.close()
    print(f"wrote {out}")
    print(f"{frames} frames of {size[0]}x{size[1]} with the {backend_name} backend in {elapsed:.1f} s")
    return 0
