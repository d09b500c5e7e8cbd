"""OpenCL platforms and devices: which device a backend traces on, what it can do, and the PoCL settings
applied before PoCL first starts. pyopencl is imported lazily here, as everywhere in the backend."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

from backends.opencl.cache import configure_caches
from engine.errors import BackendUnavailable

if TYPE_CHECKING:  # pyopencl is imported lazily: importing this module must not need it
    import pyopencl as cl

INSTALL_PYOPENCL = "pip install 'pyopencl[pocl]'"
NO_PLATFORM = (
    "no OpenCL platform found: install PoCL (pip install pocl-binary-distribution, or apt-get install "
    "pocl-opencl-icd) or your GPU vendor's OpenCL driver"
)
FP64_EXTENSION = "cl_khr_fp64"


#: PoCL settings the backend applies when the user has not set them (read once, at PoCL's init).
#: ``POCL_AFFINITY=1`` pins PoCL's worker threads to cores: PoCL 3.1, 2 cores, 800x800 f32 frames,
#: 3 alternating processes per setting: wall 82-88 vs 98-113 ms (mesh-10k), 108-140 vs 139-142 ms
#: (mesh-200k), 60-68 vs 67-78 ms (ten-boxes), CPU time unchanged (108 / 139 / 77 ms), frames
#: bit-identical. Not set (no consistent gain): POCL_WORK_GROUP_METHOD=loopvec (cbs is unknown
#: to PoCL 3.1), POCL_MAX_PTHREAD_COUNT=1 or 4, work groups 8x8, 32x8 or the driver's choice.
POCL_DEFAULTS: dict[str, str] = {"POCL_AFFINITY": "1"}


def configure_runtime() -> None:
    """Apply :data:`POCL_DEFAULTS` where unset; must run before PoCL is first initialised."""
    for name, value in POCL_DEFAULTS.items():
        os.environ.setdefault(name, value)


def import_cl() -> Any:
    """pyopencl, with the project's caches and PoCL's settings applied first."""
    configure_caches()
    configure_runtime()
    import pyopencl

    return pyopencl


def platforms() -> list[cl.Platform]:
    """Every OpenCL platform, or :class:`engine.errors.BackendUnavailable` naming what to install."""
    cl = import_cl()
    try:
        found = list(cl.get_platforms())
    except cl.Error as e:  # the ICD loader raises PLATFORM_NOT_FOUND_KHR when it finds none
        raise BackendUnavailable(f"{NO_PLATFORM} ({type(e).__name__}: {e})") from e
    if not found:
        raise BackendUnavailable(NO_PLATFORM)
    return found


def _devices(platform: cl.Platform) -> list[cl.Device]:
    cl = import_cl()
    try:
        return list(platform.get_devices())
    except cl.Error:  # DEVICE_NOT_FOUND: a platform whose driver sees no hardware
        return []


def select_device(spec: str | None = None, *, prefer_fp64: bool = False) -> cl.Device:
    """The device to trace on.

    ``spec`` (or ``$PYOPENCL_CTX``) in pyopencl's syntax, ``platform:device``,
    each an index or a name substring (``0:0``, ``portable``, ``nvidia:0``);
    without one, the first GPU, else the first CPU, else the first device
    (with ``prefer_fp64``, among the devices with doubles first, so an f64
    backend skips a GPU without them rather than failing).
    """
    cl = import_cl()
    found = platforms()
    spec = spec if spec is not None else (os.environ.get("PYOPENCL_CTX") or None)
    if spec:
        try:
            return cl.choose_devices(interactive=False, answers=spec.split(":"))[0]
        except (RuntimeError, cl.Error) as e:
            listing = "; ".join(
                f"{i}: {pf.name.strip()} [{', '.join(d.name.strip() for d in _devices(pf)) or 'no devices'}]"
                for i, pf in enumerate(found)
            )
            raise BackendUnavailable(
                f"OpenCL device {spec!r} (PYOPENCL_CTX syntax) not found: {e}; have {listing}"
            ) from None
    devices = [d for pf in found for d in _devices(pf)]
    if not devices:
        names = ", ".join(pf.name.strip() for pf in found)
        raise BackendUnavailable(f"OpenCL platform(s) {names} have no device; {NO_PLATFORM.split(': ', 1)[1]}")
    if prefer_fp64:
        devices = [d for d in devices if device_has_fp64(d)] or devices
    for kind in (cl.device_type.GPU, cl.device_type.CPU):
        for device in devices:
            if device.type & kind:
                return device
    return devices[0]


def device_kind(device: cl.Device) -> str:
    """``GPU``, ``CPU``, ``ACCELERATOR`` (joined with ``|`` when a device claims several)."""
    cl = import_cl()
    kinds = [k for k in ("GPU", "CPU", "ACCELERATOR", "CUSTOM") if device.type & getattr(cl.device_type, k, 0)]
    return "|".join(kinds) or str(device.type)


def device_has_fp64(device: cl.Device) -> bool:
    """Whether ``device`` computes in double (``cl_khr_fp64``)."""
    return FP64_EXTENSION in device.extensions.split()


def pocl_version(platform: cl.Platform) -> str | None:
    """PoCL's version from its platform string (``OpenCL 3.0 PoCL 3.0-rc2 ...``), or ``None``."""
    words = platform.version.split()
    if "PoCL" in words and words.index("PoCL") + 1 < len(words):
        return words[words.index("PoCL") + 1]
    return None


def first_line(text: str) -> str:
    """A driver message's first non-empty line (its build logs run long)."""
    return next((line.strip() for line in text.splitlines() if line.strip()), "")
