"""The ``aberrant`` command line: render a scene or demo (a frame or a flythrough), import
TelloEngine scenes, export glTF, list backends, list demos.

Every error a user can cause (a bad scene file, an unknown backend or demo, a
bad size, an output folder that does not exist) is one line on stderr,
``aberrant: error: ...``, and exit status 2, with no traceback. Outputs are
written only after the render succeeded, each through a temporary file and a
rename, so a failed run never leaves a new or half-written file behind and
never overwrites an old one.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import sys
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TypeVar

import numpy as np

from aberrant.running import PROG, check_frame_memory, one_line, with_fallback
from aberrant.signals import Terminated, terminations_raise
from engine.errors import AberrantError, shorten

if TYPE_CHECKING:
    from aberrant.levels import Level
    from backends.base import Backend, Frame
    from editor.reload import LevelWatcher

#: The largest image side ``render`` accepts (guards against typos like 80000x600).
MAX_SIDE = 16384
#: Keys of the ``--aovs`` archive: the AOVs besides colour (which is the PNG).
NPZ_AOVS = ("depth", "perceived", "instance", "events")
#: What a SCENE argument may be (resolved by aberrant/levels.py).
LEVEL_HELP = "a scene file (.json), a glTF file (.glb/.gltf), a level module (level.py[:func]) or a demo name"

T = TypeVar("T")


class UsageError(AberrantError):
    """A command-line argument is wrong."""


class _Parser(argparse.ArgumentParser):
    """argparse, but usage errors are one line like every other error (still exit status 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{PROG}: error: {message} (see '{self.prog} --help')\n")


def parse_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)``; both sides in [1, MAX_SIDE]."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", text)
    if not match:
        raise UsageError(f"--size must be WIDTHxHEIGHT in pixels, e.g. 640x480; got {text!r}")
    width, height = int(match.group(1)), int(match.group(2))
    for side, value in (("width", width), ("height", height)):
        if not 1 <= value <= MAX_SIDE:
            raise UsageError(f"--size {side} must lie in [1, {MAX_SIDE}] pixels; got {text!r}")
    return width, height


def parse_spp(value: int) -> int:
    """``--spp`` checked before anything is opened: samples a pixel, 1 to MAX_SPP."""
    from backends.samples import MAX_SPP

    if not 1 <= value <= MAX_SPP:
        raise UsageError(f"--spp (samples per pixel) must lie in [1, {MAX_SPP}]; got {value}")
    return value


def _check_output(option: str, path: Path) -> None:
    """Fail before rendering when ``path`` cannot be written (so no render time is wasted).

    What is already there must be a writable regular file, or a symlink to one
    (written through); a device, FIFO, socket or folder is refused, never replaced.
    """
    from engine.atomic_files import UnsafeTarget, check_writable

    try:
        check_writable(path)
    except UnsafeTarget as e:
        raise UsageError(f"{option} {shorten(path)}: {e.strerror}") from None


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
    _check_output("--out", out)
    npz = Path(args.aovs) if args.aovs else None
    if npz is not None:
        _check_output("--aovs", npz)
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


def _check_cluster_args(args: argparse.Namespace) -> None:
    """``--workers N`` or ``--scheduler ADDR``, not both, and N at least 1."""
    if args.workers is not None and args.scheduler is not None:
        raise UsageError("give --workers (a cluster started here) or --scheduler (a running one), not both")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")


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
    _check_cluster_args(args)
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


def cmd_import_tello(args: argparse.Namespace) -> int:
    """``import-tello``: a TelloEngine scene file to our scene format (aberrant/importers/tello.py)."""
    from aberrant.importers.tello import import_tello

    scene_file = Path(args.scene_file)
    mesh_dir = Path(args.mesh_dir) if args.mesh_dir else Path(os.path.abspath(scene_file)).parent.parent / "Mesh"
    out = Path(args.out)
    _check_output("--out", out)
    result = import_tello(scene_file, mesh_dir, out, checker=args.checker)
    result.scene.close()
    for warning in result.warnings:
        print(f"{PROG}: warning: {one_line(warning)}", file=sys.stderr)
    for path in result.mesh_files:
        print(f"wrote {path}")
    counts = ", ".join(f"{n} {kind}" for kind, n in result.counts.items())
    print(f"wrote {out} ({counts}; camera: {result.camera})")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """``export``: a level as glTF 2.0 for Blender (aberrant/exporters/gltf.py), read back by every command."""
    from aberrant.exporters.gltf import EXPORT_SUFFIXES, export_gltf
    from aberrant.levels import open_level

    out = Path(args.out)
    if out.suffix.lower() not in EXPORT_SUFFIXES:
        raise UsageError(f"{shorten(out)}: the output must be a .glb or .gltf file")
    _check_output("OUT", out)
    from components import Aberration, Mesh, Portal

    with open_level(args.scene) as level:
        export_gltf(level.scene, out)
        kinds = ((Mesh, "meshes"), (Aberration, "aberrations"), (Portal, "portals"))
        counts = ", ".join(f"{len(level.scene.query(kind))} {label}" for kind, label in kinds)
    print(f"wrote {out} ({counts})")
    return 0


def cmd_backends(args: argparse.Namespace) -> int:
    from backends.base import BACKENDS, backend_class, probe

    for name in BACKENDS:
        reason = probe(name)
        if reason is not None:
            print(f"{name}: unavailable: {reason}")
            continue
        try:
            backend = backend_class(name)()
        except Exception as e:  # probing passed yet it cannot start: report, do not crash the listing
            print(f"{name}: unavailable: {type(e).__name__}: {e}")
            continue
        try:
            info = backend.info()
        finally:
            backend.release()
        print(f"{name}: available")
        for key, value in info.items():
            print(f"  {key}: {value}")
    return 0


def cmd_demos(args: argparse.Namespace) -> int:
    from demos import demo_names, describe

    names = demo_names()
    width = max((len(n) for n in names), default=0)
    for name in names:
        print(f"{name:<{width}}  {describe(name)}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    """``bench``: speed against error for every backend and setting (aberrant/bench/)."""
    from aberrant.bench import bench_command, make_config, rerender

    if args.from_results:
        try:
            written = rerender([Path(p) for p in args.from_results], Path(args.out))
        except RecursionError:  # json's decoder recurses once per level of nesting
            raise UsageError(
                f"--from-results {shorten(' '.join(args.from_results))}: nested too deeply to be a results.json"
            ) from None
        for path in written:
            print(f"wrote {path}")
        return 0
    _check_cluster_args(args)
    config = make_config(
        scenes=args.scenes, backends=args.backends, size=parse_size(args.size) if args.size else None,
        repeat=args.repeat, out=args.out, quick=args.quick, sweeps=args.sweeps, overhead=not args.no_overhead,
        command=" ".join([PROG, *(args.argv or [])]), jobs=args.jobs, time_limit_s=args.time_limit,
        spp=parse_spp(args.spp),
    )  # fmt: skip
    if args.workers is not None or args.scheduler is not None:
        return bench_command(config, workers=args.workers, scheduler=args.scheduler)
    return bench_command(config)


def cmd_editor(args: argparse.Namespace) -> int:
    """``editor``: the level editor with play mode (needs a display and ``pip install 'aberrant[editor]'``)."""
    try:
        from editor.model import EditorModel
        from editor.window import EditorUnavailable, display_problem, run_editor
    except ImportError as e:
        raise UsageError(f"the editor needs imgui-bundle and glfw: pip install 'aberrant[editor]' ({e})") from None
    size = parse_size(args.size) if args.size is not None else None
    problem = display_problem()
    if problem is not None:
        raise UsageError(problem)
    from aberrant.levels import open_level

    model = EditorModel()
    watcher = None
    if args.scene is not None:  # a bad file, module or name fails here, before a window opens
        level = open_level(args.scene)
        model = EditorModel(level.scene, level.file if level.kind == "scene" else None, demo=level.demo or level.label)
        watcher = level_watcher(args.scene, level) if level.kind == "code" else None  # a scene file is the model's
    try:
        if size is None:
            return run_editor(model, backend=args.backend, watcher=watcher)
        return run_editor(model, backend=args.backend, size=size, watcher=watcher)
    except EditorUnavailable as e:
        raise UsageError(str(e)) from None


def level_watcher(source: str, level: Level) -> LevelWatcher | None:
    """Hot reload for a level read from a file (a demo has none to watch): rebuilt the way it was opened."""
    from aberrant.levels import open_level
    from editor.reload import LevelWatcher

    if level.file is None:
        return None
    return LevelWatcher(level.file, lambda: open_level(source).scene, level.scene)


def cmd_play(args: argparse.Namespace) -> int:
    """``play``: walk (or fly through) a level in a window with no panels (needs a display and the editor extra)."""
    try:
        from editor.player import DEFAULT_SIZE, run_player
        from editor.window import EditorUnavailable, display_problem
    except ImportError as e:
        raise UsageError(f"the player needs imgui-bundle and glfw: pip install 'aberrant[editor]' ({e})") from None
    size = parse_size(args.size) if args.size is not None else DEFAULT_SIZE
    problem = display_problem("player")
    if problem is not None:
        raise UsageError(problem)
    from aberrant.levels import open_level
    from engine.scene_writer import scene_document

    record = Path(args.record) if args.record else None
    if record is not None:
        if record.suffix.lower() != ".json":
            raise UsageError(f"--record {shorten(record)}: the camera path is saved in a scene file (.json)")
        _check_output("--record", record)
    with open_level(args.scene) as level:
        watcher = level_watcher(args.scene, level)
        template = None  # the recording goes into the level's own scene file, as it is on disk then
        if record is not None:
            template = scene_document(level.scene, Path(os.path.abspath(record)).parent)  # before play moves it
        elif level.kind == "scene" and level.file is not None and level.file.suffix.lower() == ".json":
            record = level.file
        try:
            return run_player(
                level.scene, size=size, backend=args.backend, fly=args.fly, frames=args.frames, watcher=watcher,
                record=record, record_template=template,
            )  # fmt: skip
        except EditorUnavailable as e:
            raise UsageError(str(e)) from None


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Ray trace triangle-mesh scenes in deformed space.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    render = sub.add_parser("render", help="render one frame (or, with --path, a flythrough) of a scene or demo")
    render.add_argument("scene", metavar="SCENE", help=LEVEL_HELP)
    render.add_argument(
        "--backend", default=None, help="reference, glsl, opencl or auto (default: $ABERRANT_BACKEND or auto)"
    )
    render.add_argument("--precision", choices=("f32", "f64"), default=None, help="tracing precision")
    render.add_argument("--size", default="800x600", help="WIDTHxHEIGHT in pixels (default 800x600)")
    render.add_argument(
        "--spp", type=int, default=1, metavar="N", help="samples per pixel, 1-256: anti-aliased colour (default 1)"
    )
    render.add_argument(
        "--out", default=None, help="colour image to write (default frame.png); with --path: .mp4, .gif or a folder"
    )
    render.add_argument(
        "--aovs", default=None, metavar="FILE.npz", help="also write depth, perceived, instance, events"
    )
    render.add_argument(
        "--path", action="store_true", help="render a flythrough: the demo's camera_path(), else a walk forward"
    )
    render.add_argument(
        "--frames", type=int, default=None, help="flythrough frames (default: the clip's seconds times --fps)"
    )
    render.add_argument("--fps", type=float, default=None, help="flythrough frames per second (default 30)")
    render.add_argument(
        "--duration", type=float, default=None, metavar="SECONDS", help="flythrough length (default: the path's)"
    )
    render.add_argument(
        "--workers", type=int, default=None, metavar="N",
        help="flythrough frames on a Dask cluster of N processes started here (pip install -e '.[cluster]')",
    )  # fmt: skip
    render.add_argument(
        "--scheduler", default=None, metavar="tcp://HOST:PORT", help="flythrough frames on a running Dask cluster"
    )
    render.set_defaults(func=cmd_render)

    tello = sub.add_parser("import-tello", help="convert a TelloEngine (thesis engine) scene file to a scene file")
    tello.add_argument("scene_file", metavar="SCENE_FILE", help="a TelloEngine scene file (JSON + NUL)")
    tello.add_argument("--mesh-dir", default=None, help="its mesh resources (default: ../Mesh beside its folder)")
    tello.add_argument("--out", required=True, help="scene file to write; meshes go to <out stem>_meshes/ beside it")
    tello.add_argument(
        "--checker", type=float, default=0.125, help="checker cell size in UV units, like the thesis texture (0: none)"
    )
    tello.set_defaults(func=cmd_import_tello)

    export = sub.add_parser("export", help="write a level as glTF 2.0 (.glb or .gltf) to edit in Blender")
    export.add_argument("scene", metavar="SCENE", help=LEVEL_HELP)
    export.add_argument("out", metavar="OUT.glb", help="the file to write (.glb, or .gltf with the buffer embedded)")
    export.set_defaults(func=cmd_export)

    backends = sub.add_parser("backends", help="list the tracer backends and whether they can run here")
    backends.set_defaults(func=cmd_backends)

    demos = sub.add_parser("demos", help="list the demos")
    demos.set_defaults(func=cmd_demos)

    bench = sub.add_parser("bench", help="speed against error: every backend and setting on every scene, a report")
    bench.add_argument(
        "--scenes",
        nargs="+",
        default=None,
        metavar="SCENE",
        help="scene names or groups (all, bench, demos, hard, overhead, architecture, hotel, space-count, features), "
        "scene files or level.py[:func]; "
        "default all (--quick: a few)",
    )
    bench.add_argument(
        "--backends", nargs="+", default=None, metavar="BACKEND", help="glsl, opencl, reference (default: glsl opencl)"
    )
    bench.add_argument("--size", default=None, help="WIDTHxHEIGHT (default 800x800; --quick 96x72)")
    bench.add_argument("--repeat", type=int, default=None, help="timed frames per cell (default 5; --quick 3)")
    bench.add_argument(
        "--spp", type=int, default=1, metavar="N", help="samples per pixel of the timed frames, 1-256 (default 1)"
    )
    bench.add_argument("--out", default="out/bench", help="folder for report.md, results.json, speed_vs_error.png")
    bench.add_argument("--quick", action="store_true", help="small sizes, few scenes and sweeps (under two minutes)")
    bench.add_argument(
        "--sweeps",
        nargs="+",
        default=None,
        metavar="SWEEP",
        help="all, none, or: precision max_events size leaf workgroup tables local_size spp shadows",
    )
    bench.add_argument("--no-overhead", action="store_true", help="skip the engine-overhead measurement")
    bench.add_argument(
        "--jobs", type=int, default=1, help="render the missing reference frames first, in this many processes"
    )
    bench.add_argument(
        "--time-limit",
        type=float,
        default=None,
        metavar="SECONDS",
        help="skip the scenes not begun after this long (their rows say so) and still write the report",
    )
    bench.add_argument(
        "--from-results",
        nargs="+",
        default=None,
        metavar="RESULTS.json",
        help="only re-render report and plot from results.json files (several: one table across their machines)",
    )
    bench.add_argument(
        "--workers", type=int, default=None, metavar="N",
        help="measure the cells on a Dask cluster of N processes started here (pip install -e '.[cluster]')",
    )  # fmt: skip
    bench.add_argument(
        "--scheduler", default=None, metavar="tcp://HOST:PORT", help="measure the cells on a running Dask cluster"
    )
    bench.set_defaults(func=cmd_bench)

    editor = sub.add_parser("editor", help="open the level editor (play mode included) on a scene file or demo")
    editor.add_argument("scene", metavar="SCENE", nargs="?", default=None, help=LEVEL_HELP)
    editor.add_argument("--backend", default=None, help="reference, glsl or opencl (default: the first that starts)")
    editor.add_argument("--size", default=None, help="window WIDTHxHEIGHT (default 1600x900; the window is resizable)")
    editor.set_defaults(func=cmd_editor)

    play = sub.add_parser("play", help="walk a level in a window (WASD or arrows, mouse; Tab flies, F11 fullscreen)")
    play.add_argument("scene", metavar="SCENE", help=LEVEL_HELP)
    play.add_argument("--backend", default=None, help="reference, glsl or opencl (default: the first that starts)")
    play.add_argument("--size", default=None, help="window WIDTHxHEIGHT (default 1280x720)")
    play.add_argument("--fly", action="store_true", help="start flying instead of walking")
    play.add_argument(
        "--record", default=None, metavar="FILE.json",
        help="R saves the recorded camera path in this scene file (the level with it); default: a .json level's own",
    )  # fmt: skip
    play.add_argument("--frames", type=int, default=None, help=argparse.SUPPRESS)  # tests: quit after N frames
    play.set_defaults(func=cmd_play)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``aberrant`` console script; returns the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse's --help (0) and usage errors (2)
        return int(e.code or 0) if not isinstance(e.code, str) else 2
    args.argv = list(sys.argv[1:] if argv is None else argv)
    try:
        with terminations_raise(), warnings.catch_warnings():
            # numpy's "overflow encountered in ..." from extreme (but valid) scene values says nothing a user
            # can act on; the tracers keep NaN and inf out of the image, so keep stderr for real messages.
            warnings.filterwarnings("ignore", message=r".* encountered in ", category=RuntimeWarning)
            return int(args.func(args))
    except AberrantError as e:
        print(f"{PROG}: error: {one_line(str(e))}", file=sys.stderr)
        return 2
    except OSError as e:
        where = f"{shorten(e.filename)}: " if e.filename else ""
        print(f"{PROG}: error: {where}{one_line(e.strerror or str(e))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except Terminated as e:  # SIGTERM, SIGHUP: cleaned up like Ctrl-C; the status a killed process would have
        print(f"{PROG}: terminated ({e})", file=sys.stderr)
        return 128 + e.signum


if __name__ == "__main__":
    raise SystemExit(main())
