"""Records of 4-vector fields: one declaration gives the host's structured dtype and the kernels' struct.

A :class:`Record` lists its fields (``real4`` / ``float4`` / ``int4``; 8-vectors for OpenCL's 8-wide BVH),
the subset of types on which std430 and OpenCL C agree; :meth:`Record.dtype` places each at its std430
offset and :meth:`Record.kernel_members` names the struct members ``backends/shared/layout_h.py`` writes.
The tables themselves are declared in :mod:`engine.layout`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

Precision = Literal["f32", "f64"]
PRECISIONS: tuple[Precision, ...] = ("f32", "f64")

#: A field's vector type in the kernels: ``real4`` follows the precision, the others are always 32-bit;
#: ``float8`` / ``int8`` exist in OpenCL C only (two 4-vector rows on the host).
Kind = Literal["real4", "float4", "int4", "float8", "int8"]
_LANES: dict[str, int] = {"real4": 4, "float4": 4, "int4": 4, "float8": 8, "int8": 8}


@dataclass(frozen=True)
class Field:
    """One field of a record: a dtype field and the kernel struct member(s) reading its bytes.

    ``rows > 1``: a matrix of 4-vector rows, the members ``member0``, ``member1``, ... (``member``
    defaults to ``name``). ``w``: a ``float4`` whose ``w`` holds an int32 bit pattern (the kernel reads
    it with ``AS_INT``); the host sees ``name`` as three float32 and ``w`` as an int32 field.
    """

    name: str
    kind: Kind
    rows: int = 1
    member: str = ""
    w: str = ""

    def kernel_members(self) -> list[tuple[str, str]]:
        """(kernel type, member name) of each vector this field is in the kernel's struct."""
        member = self.member or self.name
        if self.rows == 1:
            return [(self.kind, member)]
        return [(self.kind, f"{member}{row}") for row in range(self.rows)]


@dataclass(frozen=True)
class Record:
    """A packed record, declared once: ``struct`` is its name in the kernels, ``fields`` its vectors in order."""

    struct: str
    fields: tuple[Field, ...]

    def dtype(self, precision: Precision = "f32") -> np.dtype:
        """The record's dtype: each vector at its std430 offset, the whole padded to its widest vector."""
        real = np.float64 if precision == "f64" else np.float32
        names: list[str] = []
        formats: list[object] = []
        offsets: list[int] = []
        offset = 0
        align = 16
        for field in self.fields:
            base = np.dtype(real if field.kind == "real4" else np.int32 if field.kind.startswith("int") else np.float32)
            lanes = _LANES[field.kind]
            size = lanes * base.itemsize
            align = max(align, size)
            offset = -(-offset // size) * size
            if field.w:
                if field.kind != "float4" or field.rows != 1:  # pragma: no cover - a programming error in this file
                    raise ValueError(f"{self.struct}.{field.name}: only a single float4 has an int w")
                names += [field.name, field.w]
                formats += [(np.float32, (3,)), np.int32]
                offsets += [offset, offset + 12]
            else:
                shape = (field.rows, 4) if field.rows > 1 else (lanes // 4, 4) if lanes > 4 else (4,)
                names.append(field.name)
                formats.append((base, shape))
                offsets.append(offset)
            offset += size * field.rows
        itemsize = -(-offset // align) * align
        return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize})

    def kernel_members(self) -> list[tuple[str, str]]:
        """(kernel type, member name) of the struct's members, in order."""
        return [member for field in self.fields for member in field.kernel_members()]


def vectors(kind: Kind, *names: str) -> tuple[Field, ...]:
    """Fields of one kind, one vector each."""
    return tuple(Field(name, kind) for name in names)
