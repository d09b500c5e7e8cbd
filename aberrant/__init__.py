"""aberrant: ray trace triangle-mesh scenes in deformed space, from Python.

A level is a `Scene`: entities with frozen components (`Transform`, `Mesh`,
`Aberration` boxes that compress or stretch space, linked `Portal` quads, a
`Camera`), built as code or read with `load_scene`. `render` turns it into a
`Frame` of numpy arrays on a tracer backend: GLSL compute shaders, OpenCL, or
the float64 NumPy reference that defines the truth (`create_backend` opens
one; ``auto`` is the fastest that starts here). An `App` runs the real systems
tick by tick (movement through aberrations, portal teleports, upload, render),
headless or with a backend; `ScriptedInput` and camera paths (`CameraPath`,
or `route` through `Stop`s of a walk) steer its camera.

Importing this package is cheap: no GPU or OpenCL module is loaded until a
backend is opened.

>>> import aberrant
>>> scene = aberrant.Scene("hall", settings=aberrant.Settings(background=(0.5, 0.7, 0.9)))
>>> floor = scene.add_mesh("floor", "plane", scale=(20, 1, 20), checker=1.0)
>>> crate = scene.add_mesh("crate", "box", position=(0, 0.5, -3), color=(0.8, 0.3, 0.2))
>>> hall = scene.add_aberration("long", (0, 0, 1), position=(0, 1.5, -8), scale=(3, 3, 6))
>>> camera = scene.set_camera((0, 1.6, 4), look_at=(0, 1, -3))
>>> frame = aberrant.render(scene, "reference", size=(32, 24))
>>> frame.color.shape, int(frame.instance[12, 16]) == crate
((24, 32, 4), True)
>>> scene.close()

Each name below comes with a short example; the examples run as doctests.

## Scenes

`Scene`: an esper world plus assets and settings, with builder calls that
validate their input (`SceneError` names the entity and field).

>>> scene = aberrant.Scene("room")
>>> crate = scene.add_mesh("crate", "box", position=(0, 0.5, -3))
>>> scene.name_of(crate), scene.entity("crate") == crate
('crate', True)

`Settings`: what a ray sees when it hits nothing, the light, and when it gives up.

>>> aberrant.Settings(background=(0, 0, 0), max_events=8).max_events
8

`load_scene` / `save_scene`: JSON scene files, read without executing
anything and written atomically; saving is canonical.

>>> import tempfile, pathlib
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> aberrant.save_scene(scene, folder / "room.json")
>>> aberrant.load_scene(folder / "room.json").name_of(crate)
'crate'

`export_gltf`: a scene as glTF 2.0 (``.glb``) to edit in Blender; every command
opens it again (`open_level`), as the same scene.

>>> aberrant.export_gltf(scene, folder / "room.glb")
>>> with aberrant.open_level(folder / "room.glb") as level:
...     level.scene.get(level.scene.entity("crate"), aberrant.Transform).position
(0.0, 0.5, -3.0)

`build_demo` / `demo_names`: the demo levels, built as code.

>>> "endless_corridor" in aberrant.demo_names()
True
>>> corridor = aberrant.build_demo("endless_corridor")
>>> len(corridor.query(aberrant.Portal))
2

## Components

Frozen dataclasses: read them with ``scene.get``, edit an entity by handing
the scene a new value (``dataclasses.replace``), which is how a later frame
re-uploads only what changed.

`Transform`: position, rotation (quaternion x, y, z, w) and scale, world space.

>>> scene.get(crate, aberrant.Transform).position
(0.0, 0.5, -3.0)

`Mesh`: which asset an entity shows, its colour and checker cells.

>>> import dataclasses
>>> mesh = scene.get(crate, aberrant.Mesh)
>>> scene.set(crate, dataclasses.replace(mesh, color=(1, 0, 0)))
>>> scene.get(crate, aberrant.Mesh).color
(1.0, 0.0, 0.0)

`Aberration`: a box of deformed space; ``metric`` scales space by ``1 + D`` along its axes.

>>> box = scene.add_aberration("squeeze", (0, 0, -0.5), position=(0, 1, -6), scale=(2, 2, 4))
>>> scene.get(box, aberrant.Aberration).deformation
(0.0, 0.0, -0.5)

`Portal`: one end of a portal, linked by its target's name.

>>> corridor.get(corridor.entity("north_end"), aberrant.Portal).target
'south_end'

`Light`: a ``sun`` (shining along its -Z) or a ``point`` light; one that casts shadows sends shadow rays
along the camera rays' journey, through portals and boxes (a scene without one keeps the settings' sun).

>>> sun = scene.add_light("sun", "sun", look_at=(0, -1, -1))
>>> scene.get(sun, aberrant.Light).shadows
True

`Camera`: the lens and the perceived walking speed (its pose is the entity's `Transform`).

>>> camera = scene.set_camera((0, 1.6, 4), look_at=(0, 1, 0), fov_deg=50)
>>> scene.get(camera, aberrant.Camera).fov_deg
50.0

## Rendering

`render`: one frame in one call (it opens and releases a backend when given a name or none).

>>> frame = aberrant.render(scene, "reference", size=(16, 12), aovs="depth")
>>> frame.present(), frame.depth.shape
(['depth'], (12, 16))

`create_backend`: a backend you keep open for many frames (``auto``: the fastest that starts here).

>>> with aberrant.create_backend("reference") as backend:
...     frames = [aberrant.render(scene, backend, size=(16, 12)) for _ in range(2)]
>>> backend.name
'reference'

`Frame`: a rendered frame's AOVs as numpy arrays (row 0 at the top) and its timings.

>>> frame = frames[0]
>>> isinstance(frame, aberrant.Frame), frame.aov("instance").dtype.name, frame.width
(True, 'int32', 16)

## Running a scene

`App`: the tick loop; without a backend only movement and teleport run.

`ScriptedInput` / `InputState`: input for headless runs, one state per tick.

>>> walk = aberrant.ScriptedInput.repeat(aberrant.InputState(move=(0, 0, -1)), 30)
>>> _ = corridor.set_camera((0, 1.7, -4), look_at=(0, 1.7, -10), speed=3)  # 2 units before the north end
>>> with aberrant.App(corridor, input_source=walk) as app:
...     _ = app.run(30, 1 / 30)  # 3 units forward: out of the south end at z = +6, then one more
>>> round(corridor.get(corridor.camera_entity, aberrant.Transform).position[2], 6)
5.0

`CameraPath` / `Keyframe`: a smooth path through timed poses, replayed by the real systems.

>>> path = aberrant.CameraPath([
...     aberrant.Keyframe(0.0, (0, 1.6, 5), look_at=(0, 1.6, 0)),
...     aberrant.Keyframe(2.0, (0, 1.6, 1), look_at=(0, 1.6, -4)),
... ])
>>> [round(float(c), 6) for c in path.sample(1.0)[0]]  # two keyframes: a straight line at constant speed
[0.0, 1.6, 3.0]

`Stop` / `route`: a walk written in world coordinates, turned into the path the
systems replay through aberrations and portals.

>>> stops = [aberrant.Stop((0, 1.7, 3), (0, 1.7, -10)), aberrant.Stop((0, 1.7, 3), (0, 1.7, -10), via="north_end")]
>>> lap = aberrant.route(corridor, stops, hold=0.0)  # once round the endless corridor
>>> lap.place_camera(corridor)
>>> with aberrant.App(corridor, input_source=lap.inputs(corridor)) as app:
...     _ = app.run(int(lap.duration * 30), 1 / 30)
>>> [round(c, 6) for c in corridor.get(corridor.camera_entity, aberrant.Transform).position]
[0.0, 1.7, 3.0]

`AberrantError`: the base of every error a user can cause (a bad file, value or argument).

>>> try:
...     aberrant.render(scene, "reference", size=(0, 10))
... except aberrant.AberrantError as e:
...     print(e)
size must be positive, got 0x10
>>> scene.close(); corridor.close()
"""

from __future__ import annotations

from aberrant.exporters.gltf import export_gltf
from aberrant.levels import open_level
from aberrant.rendering import render
from backends.base import Frame, create_backend
from components import Aberration, Camera, Light, Mesh, Portal, Transform
from demos import build_demo, demo_names
from engine.errors import AberrantError
from engine.input import InputState, ScriptedInput
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene
from engine.settings import Settings
from systems.app import App
from systems.camera_path import CameraPath, Keyframe
from systems.route import Stop, route

__all__ = [
    "AberrantError",
    "Aberration",
    "App",
    "Camera",
    "CameraPath",
    "Frame",
    "InputState",
    "Keyframe",
    "Light",
    "Mesh",
    "Portal",
    "Scene",
    "ScriptedInput",
    "Settings",
    "Stop",
    "Transform",
    "build_demo",
    "create_backend",
    "demo_names",
    "export_gltf",
    "load_scene",
    "open_level",
    "render",
    "route",
    "save_scene",
]
