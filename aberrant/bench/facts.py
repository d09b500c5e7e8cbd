"""Facts the report states: the machine (CPU, cores, devices, Embree) and each scene's make-up."""

from __future__ import annotations

import os
import platform
import socket
from pathlib import Path
from typing import Any

import numpy as np

from aberrant.bench import embree
from aberrant.bench.scenes import SceneSpec
from backends.base import backend_class
from components import Aberration, Mesh, Portal
from engine.packing_lights import shadowing
from engine.scene import Scene


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_info(backends: list[str], probes: dict[str, str | None]) -> dict[str, Any]:
    """Host name, CPU, cores, OS, Python and each backend's device (the report names the machine)."""
    info: dict[str, Any] = {
        "name": socket.gethostname() or platform.node() or "?",
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "backends": {},
    }
    for name in backends:
        if probes.get(name) is not None:
            info["backends"][name] = {"unavailable": probes[name]}
            continue
        try:
            with backend_class(name)() as backend:
                info["backends"][name] = backend.info()
        except Exception as e:  # the report says so; the cells will say why too
            info["backends"][name] = {"unavailable": f"{type(e).__name__}: {e}"}
    reason = embree.available()
    info["embree"] = reason or f"embreex {embree.version()}"
    return info


def scene_info(spec: SceneSpec, scene: Scene) -> dict[str, Any]:
    meshes = scene.query(Mesh)
    aberrations = [a.mode for _, a in scene.query(Aberration)]
    portals = sum(1 for _, p in scene.query(Portal) if p.target is not None)
    triangles = sum(scene.asset(m.asset).triangle_count for _, m in meshes)
    return {
        "name": spec.name,
        "group": spec.group,
        "description": spec.description,
        "fixed_size": list(spec.size) if spec.size else None,
        "entities": len(scene.entities()),
        "meshes": len(meshes),
        "triangles": triangles,
        "aberrations": sorted(set(aberrations)),
        "portals": portals,
        "euclidean": not aberrations and portals == 0,
        "max_events": scene.settings.max_events,
        "shadows": shadowing(scene),
    }
