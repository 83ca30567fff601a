"""Buffer layouts described once, giving both the WGSL struct and a NumPy dtype.

Only 4-byte scalars are used (f32, u32, i32), which WGSL packs at 4-byte
alignment; the struct is padded to a multiple of 16 bytes, as uniform buffers
need. Nobody packs bytes by hand: fill a record of ``Struct.dtype`` and send
``record.tobytes()``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Struct"]

_SCALARS = {"f32": np.float32, "u32": np.uint32, "i32": np.int32}


@dataclass(frozen=True)
class Struct:
    """A WGSL struct of 4-byte scalar fields, in order."""

    name: str
    fields: tuple[tuple[str, str], ...]

    def __post_init__(self):
        for field, kind in self.fields:
            if kind not in _SCALARS:
                raise ValueError(f"field {field!r} of {self.name} must be one of {', '.join(_SCALARS)} (got {kind!r})")

    @property
    def dtype(self) -> np.dtype:
        """Padded NumPy dtype whose bytes match the WGSL struct."""
        size = 4 * len(self.fields)
        return np.dtype(
            {
                "names": [f for f, _ in self.fields],
                "formats": [_SCALARS[k] for _, k in self.fields],
                "offsets": [4 * i for i in range(len(self.fields))],
                "itemsize": (size + 15) // 16 * 16,
            }
        )

    def wgsl(self) -> str:
        """The WGSL declaration of the struct."""
        body = "\n".join(f"    {field}: {kind}," for field, kind in self.fields)
        return f"struct {self.name} {{\n{body}\n}}\n"

    def wgsl_value(self, **values) -> str:
        """A WGSL constructor expression of one struct value, e.g. ``Params(1u, 0.5f)``; every field must be given.

        For shader code generated around a value (tests, constant parameters);
        buffers take :meth:`pack`.
        """
        record = np.frombuffer(self.pack(**values), dtype=self.dtype)[0]
        suffix = {"f32": "f", "u32": "u", "i32": "i"}
        args = ", ".join(
            f"{float(record[field])!r}f" if kind == "f32" else f"{int(record[field])}{suffix[kind]}"
            for field, kind in self.fields
        )
        return f"{self.name}({args})"

    def pack(self, **values) -> bytes:
        """Bytes of one struct value; every field must be given."""
        missing = set(f for f, _ in self.fields) - set(values)
        extra = set(values) - set(f for f, _ in self.fields)
        if missing or extra:
            raise ValueError(f"{self.name}: missing fields {sorted(missing)}, unknown fields {sorted(extra)}")
        record = np.zeros((), dtype=self.dtype)
        for field, value in values.items():
            record[field] = value
        return record.tobytes()
