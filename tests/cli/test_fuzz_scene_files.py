"""Fuzzing scene files (docs/design.md section 8) and TelloEngine scene files with hypothesis.

Hostile or broken input must end in one of two ways: the file loads, or a
:class:`SceneFileError` (an AberrantError) whose message starts with the
file's path. Never another exception, never a hang; through the CLI, exit 0
or 2 with a single ``aberrant: error:`` line and no output file on failure.

Random structurally valid documents must load, save and reload to the same
bytes. The runs are deterministic (``derandomize=True``, no example
database), so CI sees the same examples every time; the crashes this fuzzing
found are pinned in ``test_fuzz_regressions.py``.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import tempfile
import warnings
from functools import cache
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fuzz_meshes import hang_guard

from aberrant.cli import main
from components import Aberration, Transform
from demos import build_demo, demo_names
from engine.assets import PRIMITIVES
from engine.scene import Scene
from engine.scene_file import SceneFileError, load_scene, save_scene

ROOT = Path(__file__).resolve().parents[2]
TELLO = Path(__file__).resolve().parents[2] / "tests" / "data" / "tello"
#: A small closed mesh written beside every generated scene that declares a file asset.
TETRA_OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
MESH_FILE = "meshes/tetra.obj"
#: A load that takes this long is a hang (real loads here take milliseconds).


def fuzz_settings(examples: int) -> settings:
    """Deterministic and database-free: CI runs the same examples every time and writes nothing."""
    return settings(
        max_examples=examples,
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


def load_or_error(path: Path) -> Scene | SceneFileError:
    """Load ``path``; the only acceptable failure is a SceneFileError that names the file first."""
    with hang_guard():
        try:
            return load_scene(path)
        except SceneFileError as e:
            assert str(e).startswith(str(path)), str(e)
            assert "\n" not in str(e), str(e)
            return e


def expect_error(path: Path, *fragments: str) -> SceneFileError:
    result = load_or_error(path)
    if isinstance(result, Scene):
        result.close()
        pytest.fail(f"{path.name} loaded, but it is invalid: {path.read_bytes()[:300]!r}")
    for fragment in fragments:
        assert fragment in str(result), str(result)
    return result


def check_loads_or_fails_cleanly(path: Path) -> None:
    result = load_or_error(path)
    if isinstance(result, Scene):
        result.close()


# --- strategies: structurally valid documents --------------------------------------------

FLOATS = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
UNIT = st.floats(min_value=0.0, max_value=1.0)
NONZERO = st.floats(min_value=-1e3, max_value=1e3).filter(lambda x: abs(x) >= 1e-6)
NAMES = st.text(st.characters(exclude_categories=("Cs",)), min_size=1, max_size=10).filter(lambda s: bool(s.strip()))


def vec(elements: st.SearchStrategy[float], n: int = 3) -> st.SearchStrategy[list[float]]:
    return st.lists(elements, min_size=n, max_size=n)


COLORS = vec(UNIT)
QUATERNIONS = (
    vec(st.floats(min_value=-1.0, max_value=1.0), 4)
    .filter(lambda q: math.sqrt(sum(c * c for c in q)) > 0.1)
    .map(lambda q: [c / math.sqrt(sum(x * x for x in q)) for c in q])
)


@st.composite
def optional_fields(draw: st.DrawFn, fields: dict[str, st.SearchStrategy[Any]]) -> dict[str, Any]:
    """Each field present or left to its default."""
    return {key: draw(strategy) for key, strategy in fields.items() if draw(st.booleans())}


@st.composite
def orientation(draw: st.DrawFn, position: list[float], camera: bool) -> dict[str, Any]:
    """None, a quaternion, Euler degrees or (cameras) a point to look at."""
    kinds = ["none", "rotation", "euler_deg", *(["look_at"] if camera else [])]
    kind = draw(st.sampled_from(kinds))
    if kind == "rotation":
        return {"rotation": draw(QUATERNIONS)}
    if kind == "euler_deg":
        return {"euler_deg": draw(vec(st.floats(min_value=-720.0, max_value=720.0)))}
    if kind == "look_at":
        offset = draw(vec(st.floats(min_value=-100.0, max_value=100.0)).filter(lambda v: max(map(abs, v)) > 1e-3))
        return {"look_at": [p + o for p, o in zip(position, offset, strict=True)]}
    return {}


@st.composite
def transforms(draw: st.DrawFn) -> dict[str, Any]:
    block: dict[str, Any] = {}
    position = draw(vec(FLOATS))
    if draw(st.booleans()):
        block["position"] = position
    block.update(draw(orientation(position, camera=False)))
    if draw(st.booleans()):
        block["scale"] = draw(st.one_of(NONZERO, vec(NONZERO)))
    return block


@st.composite
def valid_documents(draw: st.DrawFn) -> dict[str, Any]:
    """A random scene document that the scene file format (README, "Scene files") says is valid."""
    doc: dict[str, Any] = {"format": "aberrant-scene", "version": 1}
    if draw(st.booleans()):
        doc["name"] = draw(st.text(st.characters(exclude_categories=("Cs",)), max_size=20))
    doc["settings"] = draw(
        optional_fields(
            {
                "background": COLORS,
                "light_dir": vec(st.floats(min_value=-10.0, max_value=10.0)).filter(lambda v: max(map(abs, v)) > 1e-3),
                "max_events": st.integers(min_value=1, max_value=1024),
                "event_limit_color": COLORS,
                "ambient": UNIT,
            }
        )
    )
    asset_names = draw(st.lists(NAMES, max_size=3, unique=True))
    doc["assets"] = {
        name: draw(st.sampled_from([{"primitive": p} for p in PRIMITIVES] + [{"path": MESH_FILE}]))
        for name in asset_names
    }
    camera_name = None
    if draw(st.booleans()):
        position = draw(vec(FLOATS))
        camera: dict[str, Any] = {"position": position, **draw(orientation(position, camera=True))}
        camera.update(
            draw(
                optional_fields(
                    {"fov_deg": st.floats(min_value=1.0, max_value=179.0), "speed": st.floats(1e-3, 1e3), "name": NAMES}
                )
            )
        )
        camera_name = camera.get("name", "camera")
        doc["camera"] = camera
    names = draw(st.lists(NAMES.filter(lambda n: n != camera_name), max_size=6, unique=True))
    kinds = [draw(st.sets(st.sampled_from(["mesh", "aberration", "portal"]))) for _ in names]
    portals = [n for n, k in zip(names, kinds, strict=True) if "portal" in k]
    entities = []
    for name, parts in zip(names, kinds, strict=True):
        item: dict[str, Any] = {"name": name}
        if draw(st.booleans()):
            item["transform"] = draw(transforms())
        if "mesh" in parts:
            item["mesh"] = {"asset": draw(st.sampled_from([*asset_names, *PRIMITIVES]))}
            item["mesh"].update(
                draw(
                    optional_fields(
                        {"color": COLORS, "checker": st.floats(0.0, 100.0), "cull_backfaces": st.booleans()}
                    )
                )
            )
        if "aberration" in parts:
            mode = draw(st.sampled_from(["metric", "radial", "additive"]))
            low = -0.999 if mode == "metric" else -10.0
            block = {"deformation": draw(vec(st.floats(min_value=low, max_value=10.0)))}
            if mode != "metric" or draw(st.booleans()):
                block["mode"] = mode
            block.update(
                draw(
                    optional_fields(
                        {
                            "exit": st.sampled_from(["restore", "repeat", "invert"]),
                            "priority": st.integers(min_value=-(2**31), max_value=2**31 - 1),
                            "debug_draw": st.booleans(),
                            "color": COLORS,
                        }
                    )
                )
            )
            item["aberration"] = block
        if "portal" in parts:
            block = draw(optional_fields({"target": st.one_of(st.none(), st.sampled_from(portals)), "color": COLORS}))
            block.update(draw(optional_fields({"debug_draw": st.booleans()})))
            item["portal"] = block
        entities.append(item)
    doc["entities"] = entities
    return doc


def write_document(folder: Path, doc: object, name: str = "scene.json") -> Path:
    """The document as JSON beside a real mesh file (``NaN``/``Infinity`` literals allowed)."""
    (folder / "meshes").mkdir(exist_ok=True)
    (folder / MESH_FILE).write_bytes(TETRA_OBJ)
    path = folder / name
    data = doc if isinstance(doc, bytes) else json.dumps(doc, allow_nan=True, ensure_ascii=False).encode()
    path.write_bytes(data)
    return path


def doc_with(**extra: object) -> dict[str, Any]:
    """A minimal valid document (one floor), with ``extra`` top-level keys set."""
    doc: dict[str, Any] = {
        "format": "aberrant-scene",
        "version": 1,
        "entities": [{"name": "floor", "mesh": {"asset": "plane"}}],
    }
    doc.update(extra)
    return doc


# --- valid documents round-trip byte-identically ---------------------------------------------


@fuzz_settings(120)
@given(valid_documents())
def test_valid_documents_load_save_and_reload_byte_identically(doc: dict[str, Any]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = write_document(folder, doc)
        with hang_guard():
            scene = load_scene(path)
        try:
            names = [scene.name_of(e) for e in scene.entities() if e != scene.camera_entity]
            assert names == [e["name"] for e in doc["entities"]]
            for item in doc["entities"]:
                transform = scene.get(scene.entity(item["name"]), Transform)
                if "position" in item.get("transform", {}):
                    assert list(transform.position) == item["transform"]["position"]
                if "aberration" in item:
                    aberration = scene.get(scene.entity(item["name"]), Aberration)
                    assert list(aberration.deformation) == item["aberration"]["deformation"]
            save_scene(scene, folder / "first.json")
        finally:
            scene.close()
        again = load_scene(folder / "first.json")
        try:
            save_scene(again, folder / "second.json")
        finally:
            again.close()
        assert (folder / "first.json").read_bytes() == (folder / "second.json").read_bytes()


# --- invalid documents: always a SceneFileError that says where ------------------------------


def _paths(doc: object) -> list[tuple[Any, ...]]:
    """Every path into a parsed document, the root first (iterative: documents may be deep)."""
    found: list[tuple[Any, ...]] = []
    stack: list[tuple[tuple[Any, ...], object]] = [((), doc)]
    while stack:
        path, value = stack.pop()
        found.append(path)
        if isinstance(value, dict):
            stack.extend(((*path, k), v) for k, v in reversed(list(value.items())))
        elif isinstance(value, list):
            stack.extend(((*path, i), v) for i, v in reversed(list(enumerate(value))))
    return found


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        doc = doc[key]
    return doc


def _leaves(doc: object) -> list[tuple[Any, ...]]:
    """Paths of scalars and of arrays of scalars (the values the reader checks)."""
    out = []
    for path in _paths(doc):
        value = _get(doc, path)
        scalar_list = isinstance(value, list) and all(not isinstance(v, dict | list) for v in value)
        if path and path[-1] != "entities" and (not isinstance(value, dict | list) or scalar_list):
            out.append(path)
    return out


def _objects(doc: object) -> list[tuple[Any, ...]]:
    return [p for p in _paths(doc) if isinstance(_get(doc, p), dict)]


def _numbers(doc: object) -> list[tuple[Any, ...]]:
    return [
        p for p in _paths(doc) if p and isinstance(_get(doc, p), int | float) and not isinstance(_get(doc, p), bool)
    ]


def _fresh(doc: dict[str, Any], base: str) -> str:
    taken = {e["name"] for e in doc["entities"]} | {doc.get("camera", {}).get("name", "camera")}
    name = base
    while name in taken:
        name += "_"
    return name


#: A broken entity and the words its error must contain (out-of-range values and missing parts).
BAD_ENTITIES: list[tuple[dict[str, Any], tuple[str, ...]]] = [
    ({"transform": {"scale": [0.0, 1.0, 1.0]}}, ("transform.scale[0]",)),
    ({"transform": {"rotation": [0.0, 0.0, 0.0, 2.0]}}, ("transform.rotation", "unit length")),
    ({"transform": {"rotation": [0, 0, 0, 1], "euler_deg": [0, 0, 0]}}, ("give only one",)),
    ({"transform": {"position": [1.0, 2.0]}}, ("transform.position", "expected 3 numbers")),
    ({"mesh": {"asset": "box", "color": [1.5, 0.0, 0.0]}}, ("mesh.color[0]",)),
    ({"mesh": {"asset": "box", "checker": -1.0}}, ("mesh.checker",)),
    ({"mesh": {"color": [1.0, 1.0, 1.0]}}, ("mesh.asset",)),
    ({"mesh": {"asset": "no_such_asset"}}, ("mesh.asset", "no_such_asset")),
    ({"aberration": {"deformation": [-1.0, 0.0, 0.0]}}, ("aberration.deformation[0]",)),
    ({"aberration": {"deformation": [0, 0, 0], "mode": "warp"}}, ("aberration.mode",)),
    ({"aberration": {"deformation": [0, 0, 0], "exit": "stay"}}, ("aberration.exit",)),
    ({"aberration": {"deformation": [0, 0, 0], "priority": 2**31}}, ("aberration.priority",)),
    ({"aberration": {"deformation": [0, 0, 0], "priority": 1.5}}, ("aberration.priority",)),
    ({"portal": {"target": "nowhere_at_all"}}, ("portal.target", "nowhere_at_all")),
    ({"portal": {"target": ""}}, ("portal.target",)),
    ({"portal": {"debug_draw": 1}}, ("portal.debug_draw",)),
    ({"name": None}, ("name",)),
    ({"name": "   "}, ("name",)),
    ({"bogus_key": 1}, ("bogus_key",)),
]
#: A broken document-level block and the words its error must contain.
BAD_BLOCKS: list[tuple[str, object, tuple[str, ...]]] = [
    ("settings", {"max_events": 0}, ("settings.max_events",)),
    ("settings", {"max_events": 1025}, ("settings.max_events",)),
    ("settings", {"ambient": 1.5}, ("settings.ambient",)),
    ("settings", {"light_dir": [0, 0, 0]}, ("settings.light_dir",)),
    ("settings", {"background": [0, 0, 2]}, ("settings.background[2]",)),
    ("settings", [], ("settings", "expected an object")),
    ("camera", {"fov_deg": 0.5}, ("camera.fov_deg",)),
    ("camera", {"fov_deg": 180}, ("camera.fov_deg",)),
    ("camera", {"speed": 0}, ("camera.speed",)),
    ("camera", {"position": [0, 0, 0], "look_at": [0, 0, 0]}, ("camera.look_at",)),
    ("camera", {"position": [0, 0, 0], "look_at": [1e308, 0, -1e308]}, ("camera.look_at",)),
    ("assets", {"a": {"primitive": "teapot"}}, ("assets.a.primitive",)),
    ("assets", {"a": {"primitive": "box", "path": "x.obj"}}, ("assets.a",)),
    ("assets", {"a": {"path": "missing.obj"}}, ("assets.a", "not found")),
    ("assets", {"a": {"path": "x\u0000.obj"}}, ("assets.a", "not a usable file path")),
    ("assets", {"": {"primitive": "box"}}, ("assets",)),
    ("entities", {"name": "x"}, ("entities", "expected an array")),
    ("format", "something-else", ("format",)),
    ("version", 2, ("version",)),
    ("version", "1", ("version",)),
    ("name", 7, ("name",)),
]


@st.composite
def invalid_documents(draw: st.DrawFn) -> tuple[bytes, tuple[str, ...]]:
    """A document that must fail, and words its error must contain (none when the place varies)."""
    doc = draw(valid_documents())
    kind = draw(
        st.sampled_from(
            [
                "wrong_type", "unknown_key", "bad_entity", "bad_block", "delete_required", "dangling_target",
                "target_not_portal", "duplicate_name", "duplicate_key", "non_finite", "huge_number", "deep_nesting",
                "non_utf8", "truncated", "empty", "bom", "lone_surrogate", "not_an_object",
            ]
        )
    )  # fmt: skip
    text = lambda d: json.dumps(d, allow_nan=True, ensure_ascii=False).encode()  # noqa: E731
    if kind == "wrong_type":
        leaves = _leaves(doc)
        path = draw(st.sampled_from(leaves))
        value = _get(doc, path)
        _get(doc, path[:-1])[path[-1]] = 1.5 if isinstance(value, str) else {"k": 1}
        if path[-1] == "target" and isinstance(value, str):
            _get(doc, path[:-1])[path[-1]] = {"k": 1}
        return text(doc), ()
    if kind == "unknown_key":
        path = draw(st.sampled_from(_objects(doc)))
        _get(doc, path)["bogus_key"] = 1
        return text(doc), ()
    if kind == "bad_entity":
        parts, words = copy.deepcopy(draw(st.sampled_from(BAD_ENTITIES)))
        doc["entities"].append({"name": _fresh(doc, "zz_bad"), **parts})
        return text(doc), words
    if kind == "bad_block":
        key, value, words = copy.deepcopy(draw(st.sampled_from(BAD_BLOCKS)))
        if key == "assets":  # beside the valid assets, which entities may use
            doc["assets"].update(value)
        else:
            doc[key] = value
        return text(doc), words
    if kind == "delete_required":
        options = [("format",), ("version",)]
        options += [("entities", i, "name") for i in range(len(doc["entities"]))]
        options += [("entities", i, "mesh", "asset") for i, e in enumerate(doc["entities"]) if "mesh" in e]
        path = draw(st.sampled_from(options))
        del _get(doc, path[:-1])[path[-1]]
        return text(doc), ()
    if kind == "dangling_target":
        doc["entities"].append({"name": _fresh(doc, "zz_portal"), "portal": {"target": "zz_nowhere"}})
        return text(doc), ("portal.target", "zz_nowhere")
    if kind == "target_not_portal":
        plain = _fresh(doc, "zz_plain")
        doc["entities"].append({"name": plain})
        doc["entities"].append({"name": _fresh(doc, "zz_portal"), "portal": {"target": plain}})
        return text(doc), ("portal.target", "is not a portal")
    if kind == "duplicate_name":
        doc["entities"] += [{"name": "zz_twice"}, {"name": "zz_twice"}]
        return text(doc), ("zz_twice",)
    if kind == "duplicate_key":
        return b'{"format": "aberrant-scene", "version": 1, "version": 1}', ("appears more than once",)
    if kind in ("non_finite", "huge_number"):
        numbers = _numbers(doc)
        if not numbers:
            doc["settings"] = {"ambient": 0.5}
            numbers = [("settings", "ambient")]
        path = draw(st.sampled_from(numbers))
        huge = ["1e400", "-1e999", "1" + "0" * 400, "9" * 5000]
        literal = draw(st.sampled_from(["NaN", "Infinity", "-Infinity"] if kind == "non_finite" else huge))
        _get(doc, path[:-1])[path[-1]] = "\u0000HUGE\u0000"
        return text(doc).replace(b'"\\u0000HUGE\\u0000"', literal.encode()), ()
    if kind == "deep_nesting":
        depth = draw(st.sampled_from([2, 50, 5000, 200_000]))
        path = draw(st.sampled_from(_leaves(doc)))
        _get(doc, path[:-1])[path[-1]] = "\u0000DEEP\u0000"
        return text(doc).replace(b'"\\u0000DEEP\\u0000"', b"[" * depth + b"]" * depth), ()
    if kind == "non_utf8":
        data = text(doc)
        at = draw(st.integers(0, len(data)))
        return data[:at] + draw(st.sampled_from([b"\xff", b"\xc3\x28", b"\xed\xa0\x80", b"\x80\x80"])) + data[at:], (
            "not UTF-8",
        )
    if kind == "truncated":
        data = text(doc)
        return data[: draw(st.integers(0, len(data) - 1))], ()
    if kind == "empty":
        return draw(st.sampled_from([b"", b" ", b"\n\n", b"\t"])), ("malformed JSON",)
    if kind == "bom":
        return b"\xef\xbb\xbf" + text(doc), ("malformed JSON",)
    if kind == "lone_surrogate":
        doc["entities"].append({"name": _fresh(doc, "zz_") + "\udc80"})
        return json.dumps(doc).encode(), ("lone UTF-16 surrogate",)
    value = draw(st.sampled_from([[], "scene", 1, None, True, [doc]]))
    return json.dumps(value).encode(), ("expected an object",)


@fuzz_settings(250)
@given(invalid_documents())
def test_invalid_documents_give_a_scene_file_error_naming_the_file(case: tuple[bytes, tuple[str, ...]]) -> None:
    data, words = case
    with tempfile.TemporaryDirectory() as tmp:
        expect_error(write_document(Path(tmp), data), *words)


# --- mutated demo files -----------------------------------------------------------------------


@cache
def demo_texts() -> dict[str, bytes]:
    """Every demo saved to JSON (file assets get absolute paths, so the texts load from any folder)."""
    texts = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in demo_names():
            scene = build_demo(name)
            try:
                save_scene(scene, Path(tmp) / f"{name}.json")
            finally:
                scene.close()
            texts[name] = (Path(tmp) / f"{name}.json").read_bytes()
    return texts


JUNK_VALUES = st.sampled_from(
    [None, True, False, 0, -1, 1.5, -0.0, 1e308, -1e308, 2**31, 2**64, "", "x", "box", [], [1], [1, 2, 3], {}, {"a": 1}]
)


@st.composite
def mutated_demos(draw: st.DrawFn) -> bytes:
    """A demo's file after one to three random edits: delete a key, change a value's type, splice, truncate."""
    data = demo_texts()[draw(st.sampled_from(demo_names()))]
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["delete", "retype", "splice", "truncate", "overwrite"]))
        if op in ("delete", "retype"):
            try:
                doc = json.loads(data)
            except ValueError:
                op = "splice"
            else:
                paths = _paths(doc)[1:]
                path = paths[draw(st.integers(0, len(paths) - 1))]
                parent = _get(doc, path[:-1])
                if op == "delete":
                    del parent[path[-1]]
                else:
                    parent[path[-1]] = copy.deepcopy(draw(JUNK_VALUES))
                data = json.dumps(doc, allow_nan=True, ensure_ascii=False).encode()
                continue
        at = draw(st.integers(0, len(data)))
        if op == "splice":
            cut = draw(st.integers(0, 8))
            data = data[:at] + draw(st.binary(max_size=8)) + data[at + cut :]
        elif op == "truncate":
            data = data[:at]
        else:
            data = (
                data[:at]
                + draw(st.sampled_from([b"0", b"-", b"e", b".", b",", b"]", b"}", b'"', b"n"]))
                + data[at + 1 :]
            )
    return data


@fuzz_settings(200)
@given(mutated_demos())
def test_mutated_demo_files_load_or_fail_cleanly(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        check_loads_or_fails_cleanly(write_document(Path(tmp), data))


# --- the same through the CLI --------------------------------------------------------------------


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``main(argv)``: exit status, stdout, stderr. Python warnings (which pytest would otherwise
    intercept before they reach stderr) count as stderr lines."""
    out, err = io.StringIO(), io.StringIO()
    with (
        hang_guard(),
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(err),
        warnings.catch_warnings(record=True) as caught,
    ):
        warnings.simplefilter("always")
        code = main(argv)
    shown = "".join(f"{w.filename}:{w.lineno}: {w.category.__name__}: {w.message}\n" for w in caught)
    return code, out.getvalue(), shown + err.getvalue()


def assert_clean_cli_result(code: int, stderr: str, outputs: list[Path]) -> None:
    """Exit 0 with every output written and a silent stderr, or exit 2 with one error line and no output."""
    assert "Traceback" not in stderr, stderr
    if code == 0:
        assert stderr == "", stderr
        assert all(p.is_file() for p in outputs)
        return
    assert code == 2, (code, stderr)
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("aberrant: error: "), stderr
    assert not any(p.exists() for p in outputs)


@fuzz_settings(80)
@given(
    st.one_of(
        valid_documents().map(lambda d: json.dumps(d).encode()),
        invalid_documents().map(lambda c: c[0]),
        mutated_demos(),
    )
)
def test_cli_render_of_any_file_exits_0_or_2_with_one_line(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        scene = write_document(folder, data)
        png, npz = folder / "out.png", folder / "out.npz"
        argv = ["render", str(scene), "--backend", "reference", "--size", "8x6", "--out", str(png), "--aovs", str(npz)]
        code, _, stderr = run_cli(argv)
        assert_clean_cli_result(code, stderr, [png, npz])
        leftovers = sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))
        assert leftovers == []


# --- TelloEngine scene files ------------------------------------------------------------------


def tello_required() -> None:
    """The samples ship in tests/data/tello: a missing folder is a broken checkout, not a reason to skip."""
    assert (TELLO / "Scenes").is_dir(), f"the TelloEngine samples are missing from {TELLO}"


@cache
def tello_scenes() -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((TELLO / "Scenes").iterdir())}


TELLO_JUNK = st.sampled_from(
    [None, True, 0, -1, 3, 6, 7, 8, 1e308, -1e308, 2**31, 2**64, 10**400, "", "x", [], [0, 0, 0], [0, 0, 0, 0],
     [1e308, 1e308, 1e308], [1e-300, 1e-300, 1e-300], [1e308, 1e308, 0, 0], {}, {"type": 99}]
)  # fmt: skip


@st.composite
def mutated_tello_scenes(draw: st.DrawFn) -> bytes:
    """A TelloEngine sample after random edits: values of other types and sizes, deletions, duplicated objects,
    spliced bytes, truncation."""
    data = tello_scenes()[draw(st.sampled_from(sorted(tello_scenes())))]
    if draw(st.integers(0, 4)) == 0:
        at = draw(st.integers(0, len(data)))
        return data[:at] + draw(st.binary(max_size=6)) + data[at + draw(st.integers(0, 6)) :]
    doc = json.loads(data.rstrip(b"\0"))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(doc)[1:]
        if not paths:
            break
        path = paths[draw(st.integers(0, len(paths) - 1))]
        parent = _get(doc, path[:-1])
        op = draw(st.sampled_from(["delete", "junk", "junk", "duplicate"]))
        if op == "delete":
            del parent[path[-1]]
        elif op == "duplicate" and isinstance(parent, list):
            parent.append(json.loads(json.dumps(parent[path[-1]])))
        else:
            parent[path[-1]] = copy.deepcopy(draw(TELLO_JUNK))  # later edits must not change the strategy's value
    return json.dumps(doc, allow_nan=True).encode() + b"\0"


@fuzz_settings(60)
@given(mutated_tello_scenes())
def test_mutated_tello_scenes_import_or_fail_with_one_line(data: bytes) -> None:
    tello_required()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        source = folder / "Scene"
        source.write_bytes(data)
        out = folder / "out" / "scene.json"
        out.parent.mkdir()
        argv = ["import-tello", str(source), "--mesh-dir", str(TELLO / "Mesh"), "--out", str(out)]
        code, _, stderr = run_cli(argv)
        assert "Traceback" not in stderr and "Warning:" not in stderr, stderr
        if code == 0:
            assert all(line.startswith("aberrant: warning: ") for line in stderr.splitlines()), stderr
            scene = load_scene(out)  # what the importer wrote is a valid scene file
            scene.close()
        else:
            assert code == 2, (code, stderr)
            lines = stderr.splitlines()
            assert len(lines) == 1 and lines[0].startswith("aberrant: error: "), stderr
            assert not out.exists()


def test_generated_documents_are_what_the_design_allows():
    """The valid-document strategy really produces every component kind (a guard against a silently narrow fuzzer)."""
    seen: set[str] = set()

    @fuzz_settings(200)
    @given(valid_documents())
    def collect(doc: dict[str, Any]) -> None:
        for item in doc["entities"]:
            seen.update(k for k in ("mesh", "aberration", "portal", "transform") if k in item)
        seen.update(k for k in ("camera", "settings") if doc.get(k))
        seen.update("asset:" + next(iter(v)) for v in doc["assets"].values())

    collect()
    assert {"mesh", "aberration", "portal", "transform", "camera", "settings", "asset:path", "asset:primitive"} <= seen
