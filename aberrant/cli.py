"""The ``aberrant`` command line: render a scene or demo (a frame or a flythrough), import
TelloEngine scenes, export glTF, list backends, list demos.

Every error a user can cause (a bad scene file, an unknown backend or demo, a
bad size, an output folder that does not exist) is one line on stderr,
``aberrant: error: ...``, and exit status 2, with no traceback. Outputs are
written only after the command succeeded, each through a temporary file and a
rename, so a failed run never leaves a new or half-written file behind and
never overwrites an old one. The commands that render or open a window live in
render_command.py and window_commands.py; the argument checks they share in
arguments.py.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from aberrant.arguments import UsageError, check_cluster_args, check_target, parse_size, parse_spp
from aberrant.render_command import cmd_render
from aberrant.running import PROG, one_line
from aberrant.signals import Terminated, terminations_raise
from aberrant.window_commands import cmd_editor, cmd_play
from engine.errors import AberrantError, shorten

#: What a SCENE argument may be (resolved by aberrant/levels.py).
LEVEL_HELP = "a scene file (.json), a glTF file (.glb/.gltf), a level module (level.py[:func]) or a demo name"


class _Parser(argparse.ArgumentParser):
    """argparse, but usage errors are one line like every other error (still exit status 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{PROG}: error: {message} (see '{self.prog} --help')\n")


def cmd_import_tello(args: argparse.Namespace) -> int:
    """``import-tello``: a TelloEngine scene file to our scene format (aberrant/importers/tello.py)."""
    from aberrant.importers.tello import import_tello

    scene_file = Path(args.scene_file)
    mesh_dir = Path(args.mesh_dir) if args.mesh_dir else Path(os.path.abspath(scene_file)).parent.parent / "Mesh"
    out = Path(args.out)
    check_target("--out", out)
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
    check_target("OUT", out)
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
    check_cluster_args(args)
    config = make_config(
        scenes=args.scenes, backends=args.backends, size=parse_size(args.size) if args.size else None,
        repeat=args.repeat, out=args.out, quick=args.quick, sweeps=args.sweeps, overhead=not args.no_overhead,
        command=" ".join([PROG, *(args.argv or [])]), jobs=args.jobs, time_limit_s=args.time_limit,
        spp=parse_spp(args.spp),
    )  # fmt: skip
    if args.workers is not None or args.scheduler is not None:
        return bench_command(config, workers=args.workers, scheduler=args.scheduler)
    return bench_command(config)


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
