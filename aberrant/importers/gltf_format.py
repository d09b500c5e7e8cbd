"""The glTF 2.0 container, decoded: a ``.gltf`` (JSON and its buffers) or a ``.glb`` (JSON and BIN chunks).

Reading the file, its buffers (in the GLB, data URIs or files beside it) and
accessors is kept apart from :mod:`aberrant.importers.gltf`, which maps nodes
onto our components, as the Tello importer keeps its format apart. Every
problem is a :class:`GltfError` naming the file (and, where known, the node and field).
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np

from engine.errors import AberrantError, shorten

_COMPONENT_TYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


class GltfError(AberrantError, ValueError):
    """A glTF file cannot be opened; the one-line message names the file, the node and the field."""


class GltfFile:
    """One parsed glTF document with its buffers; reads accessors and names where a problem is."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.file = shorten(path)
        try:
            self.data = path.read_bytes()
        except OSError as e:
            raise GltfError(f"{self.file}: cannot read the file ({e.strerror or e})") from None
        self.bin: bytes | None = None
        self.doc = self.parse()
        self.buffers: dict[int, bytes] = {}

    def fail(self, message: str, *, node: str | None = None, field: str | None = None) -> GltfError:
        parts = [self.file] + ([f"node {node!r}"] if node is not None else [])
        parts += [f"field {field!r}"] if field is not None else []
        return GltfError(": ".join([*parts, message]))

    def parse(self) -> dict[str, Any]:
        text = self.data
        if self.data[:4] == b"glTF":
            text = self.glb_chunks()
        try:
            doc = json.loads(text.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise self.fail(f"not glTF JSON ({e})") from None
        if not isinstance(doc, dict) or not str(doc.get("asset", {}).get("version", "")).startswith("2"):
            raise self.fail("not a glTF 2.0 document", field="asset.version")
        return doc

    def glb_chunks(self) -> bytes:
        """The JSON chunk of a GLB; its BIN chunk is kept as buffer 0."""
        data = self.data
        if len(data) < 20:
            raise self.fail("truncated GLB header")
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise self.fail(f"GLB version {version} is not supported (only 2)")
        offset, json_chunk = 12, None
        while offset + 8 <= min(length, len(data)):
            size, kind = struct.unpack_from("<II", data, offset)
            chunk = data[offset + 8 : offset + 8 + size]
            if len(chunk) != size:
                raise self.fail("truncated GLB chunk")
            if kind == 0x4E4F534A and json_chunk is None:
                json_chunk = chunk
            elif kind == 0x004E4942 and self.bin is None:
                self.bin = chunk
            offset += 8 + size
        if json_chunk is None:
            raise self.fail("GLB without a JSON chunk")
        return json_chunk

    def items(self, key: str) -> list[Any]:
        value = self.doc.get(key, [])
        if not isinstance(value, list):
            raise self.fail("expected an array", field=key)
        return value

    def item(self, key: str, index: object, *, node: str | None, field: str) -> dict[str, Any]:
        items = self.items(key)
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(items):
            raise self.fail(f"no {key} entry {index!r} (the file has {len(items)})", node=node, field=field)
        value = items[index]
        if not isinstance(value, dict):
            raise self.fail("expected an object", field=f"{key}[{index}]")
        return value

    def buffer(self, index: int, node: str | None, field: str) -> bytes:
        if index in self.buffers:
            return self.buffers[index]
        spec = self.item("buffers", index, node=node, field=field)
        uri = spec.get("uri")
        where = f"buffers[{index}].uri"
        if uri is None:
            if self.bin is None:
                raise self.fail("the buffer has no uri and the file no GLB binary chunk", node=node, field=where)
            data = self.bin
        elif not isinstance(uri, str):
            raise self.fail("expected a string", node=node, field=where)
        elif uri.startswith("data:"):
            try:
                data = base64.b64decode(uri.partition(",")[2], validate=True)
            except ValueError as e:
                raise self.fail(f"bad base64 data URI ({e})", node=node, field=where) from None
        else:
            target = self.path.parent / uri
            try:
                data = target.read_bytes()
            except OSError as e:
                raise self.fail(f"missing buffer {uri!r} ({e.strerror or e})", node=node, field=where) from None
        if len(data) < int(spec.get("byteLength", 0)):
            raise self.fail(f"holds {len(data)} bytes, byteLength says {spec['byteLength']}", node=node, field=where)
        self.buffers[index] = data
        return data

    def accessor(self, index: object, node: str, field: str) -> np.ndarray:
        """An accessor's elements as an ``(count, width)`` array."""
        acc = self.item("accessors", index, node=node, field=field)
        where = f"accessors[{index}]"
        if "sparse" in acc:
            raise self.fail("sparse accessors are not supported", node=node, field=f"{where}.sparse")
        dtype = _COMPONENT_TYPES.get(acc.get("componentType"))  # type: ignore[arg-type]
        width = _WIDTHS.get(acc.get("type"))  # type: ignore[arg-type]
        count = acc.get("count")
        if dtype is None or width is None or not isinstance(count, int) or count < 0:
            raise self.fail("unsupported componentType, type or count", node=node, field=where)
        view = self.item("bufferViews", acc.get("bufferView"), node=node, field=f"{where}.bufferView")
        data = self.buffer(view.get("buffer"), node, f"{where}.bufferView")  # type: ignore[arg-type]
        item = np.dtype(dtype).itemsize * width
        stride = int(view.get("byteStride", item))
        start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
        end = start + (stride * (count - 1) + item if count else 0)
        if end > int(view.get("byteOffset", 0)) + int(view.get("byteLength", 0)) or end > len(data):
            raise self.fail("reads past the end of its buffer view", node=node, field=where)
        raw = np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start) if count else np.zeros(0, np.uint8)
        rows = [raw[i * stride : i * stride + item] for i in range(count)] if stride != item else [raw]
        return np.concatenate(rows).view(dtype).reshape(count, width) if count else np.zeros((0, width), dtype)
