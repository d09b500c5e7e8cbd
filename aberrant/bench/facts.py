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
    """The CPU's model name, with its family, model and widest vector extension where /proc/cpuinfo says:
    cloud machines of one name ("AMD EPYC") differ by generation, and the tracers' speed with them."""
    fields: dict[str, str] = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            key = key.strip()
            if not key and fields:
                break  # the first processor's block is enough
            fields.setdefault(key, value.strip())
    except OSError:
        pass
    name = fields.get("model name") or platform.processor() or platform.machine()
    return f"{name} ({cpu_generation(fields)})" if "cpu family" in fields else name


def cpu_generation(fields: dict[str, str]) -> str:
    """'family F model M, V' from one processor's /proc/cpuinfo fields, V the widest of AVX-512, AVX2, SSE."""
    flags = set(fields.get("flags", "").split())
    vector = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE"
    return f"family {fields.get('cpu family', '?')} model {fields.get('model', '?')}, {vector}"


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
