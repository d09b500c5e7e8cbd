"""The ``features`` scenes: what each image feature costs, as the starter demo with it against without it.

Each case is a variant of the starter demo (lit by one sun, textured crate,
slab and wall, smooth knot, plinth and ball) timed against a plainer twin,
frames alternated (``SceneSpec.baseline``), so the paired ratio is what the
feature adds: textures and smooth normals against the same scene flat; one
sun with shadows, and one without, against no Light entity (the implicit
sun, which casts none), so the shadow rays' own share shows; and four
samples a pixel against one (``SceneSpec.spp``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from components import Light, Mesh
from engine.errors import AberrantError
from engine.scene import Scene

#: The scene every case varies.
SCENE = "starter"
PREFIX = "features-"


def starter(folder: Path | None = None) -> Scene:
    from demos import build_demo

    return build_demo(SCENE)


def flat(scene: Scene) -> Scene:
    """The scene with every mesh's texture taken off and its smooth normals off."""
    for entity, mesh in scene.query(Mesh):
        scene.set(entity, replace(mesh, texture="", smooth=False))
    return scene


def unlit(scene: Scene) -> Scene:
    """The scene without Light entities (the implicit sun lights it, casting no shadows)."""
    for entity, _ in scene.query(Light):
        scene.delete(entity)
    return scene


def one_sun(scene: Scene, shadows: bool) -> Scene:
    """The scene lit by its first sun alone, casting shadows or not."""
    lights = scene.query(Light)
    suns = [(entity, light) for entity, light in lights if light.kind == "sun"]
    if not suns:
        raise AberrantError(f"the {scene.name!r} scene has no sun to keep")
    for entity, _ in lights:
        if entity != suns[0][0]:
            scene.delete(entity)
    entity, light = suns[0]
    scene.set(entity, replace(light, shadows=shadows))
    return scene


@dataclass(frozen=True)
class Feature:
    """One case: the scene with the feature, its twin without, the goal on their ratio (``None``: none)."""

    name: str
    what: str
    build: Callable[[Path], Scene]
    plain: Callable[[Path], Scene]
    goal: float | None = None
    spp: tuple[int, int] | None = None


def _lit(shadows: bool) -> Callable[[Path], Scene]:
    return lambda folder: one_sun(starter(), shadows)


def _flat(folder: Path) -> Scene:
    return flat(starter())


def _unlit(folder: Path) -> Scene:
    return unlit(starter())


FEATURES: tuple[Feature, ...] = (
    Feature(f"{PREFIX}shading", "textures + smooth normals / flat", starter, _flat, 1.1),
    Feature(f"{PREFIX}sun-shadows", "one sun with shadows / no lights", _lit(True), _unlit, 1.8),
    Feature(f"{PREFIX}sun", "one sun without shadows / no lights", _lit(False), _unlit),
    Feature(f"{PREFIX}spp4", "4 samples a pixel / 1", starter, starter, spp=(4, 1)),
)
