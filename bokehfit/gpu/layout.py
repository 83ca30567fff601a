"""Buffer layouts described once, giving the WGSL struct, its byte offsets and a NumPy dtype.

A :class:`Struct` is a list of named fields, each a 4-byte scalar (``f32``,
``u32``, ``i32``) or a vector of them (``vec2f``, ``vec3f``, ``vec4f`` and the
``u``/``i`` kinds). It places them as WGSL does (the WGSL specification's
"Memory Layout": every field at the next multiple of its alignment; vec2 aligns
to 8 bytes, vec3 and vec4 to 16, a vec3 is 12 bytes long so that a scalar may
follow in its last 4), computes the padding itself and pads the struct to a
multiple of 16 bytes, as uniform buffers need. Nobody writes offsets or pad
fields by hand: fill a record of ``Struct.dtype`` (a vector field takes a
sequence) and send ``record.tobytes()``, or call :meth:`Struct.pack`.

The WGSL declaration is generated from the same description (:meth:`Struct.wgsl`,
the generated include of the struct's name in :func:`bokehfit.gpu.shaders.load_shader`),
and :meth:`Struct.check_wgsl` compares a declaration written elsewhere with it.
The browser viewer packs its uniform from :meth:`Struct.layout_json`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["Member", "Struct", "WGSL_TYPES", "UNIFORM_ALIGN"]

#: Scalar types: NumPy type and the suffix of a WGSL literal.
_SCALARS = {"f32": (np.float32, "f"), "u32": (np.uint32, "u"), "i32": (np.int32, "i")}
#: Every field type a Struct takes: (scalar, components, alignment, size in bytes), as WGSL
#: lays them out in both the uniform and the storage address space.
WGSL_TYPES: dict[str, tuple[str, int, int, int]] = {
    **{scalar: (scalar, 1, 4, 4) for scalar in _SCALARS},
    **{
        f"vec{n}{scalar[0]}": (scalar, n, align, 4 * n)
        for scalar in _SCALARS
        for n, align in ((2, 8), (3, 16), (4, 16))
    },
}
#: A uniform buffer's struct is padded to a multiple of this many bytes.
UNIFORM_ALIGN = 16

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
#: ``vec3<f32>`` spelled as ``vec3f`` (both are WGSL).
_LONG_VECTOR = re.compile(r"vec([234])<\s*(f32|u32|i32)\s*>")


def _round_up(value: int, multiple: int) -> int:
    return -(-value // multiple) * multiple


@dataclass(frozen=True)
class Member:
    """One field of a :class:`Struct`, placed: its WGSL type and its byte offset."""

    name: str
    kind: str
    offset: int

    @property
    def scalar(self) -> str:
        """``f32``, ``u32`` or ``i32``: the type of each component."""
        return WGSL_TYPES[self.kind][0]

    @property
    def components(self) -> int:
        return WGSL_TYPES[self.kind][1]

    @property
    def align(self) -> int:
        return WGSL_TYPES[self.kind][2]

    @property
    def size(self) -> int:
        return WGSL_TYPES[self.kind][3]


@dataclass(frozen=True)
class Struct:
    """A WGSL struct of scalar and vector fields, in order, laid out by WGSL's rules.

    Examples
    --------
    >>> s = Struct("Light", (("intensity", "f32"), ("position", "vec3f"), ("index", "u32")))
    >>> [(m.name, m.offset) for m in s.members], s.size, s.dtype.itemsize
    ([('intensity', 0), ('position', 16), ('index', 28)], 32, 32)
    """

    name: str
    fields: tuple[tuple[str, str], ...]

    def __post_init__(self):
        object.__setattr__(self, "fields", tuple((str(f), str(k)) for f, k in self.fields))
        if not _IDENTIFIER.match(self.name):
            raise ValueError(f"struct name must be a WGSL identifier (got {self.name!r})")
        names = [f for f, _ in self.fields]
        if not names:
            raise ValueError(f"{self.name} has no fields")
        if len(set(names)) != len(names):
            raise ValueError(f"{self.name}: field names must be unique (got {names})")
        for field, kind in self.fields:
            if not _IDENTIFIER.match(field):
                raise ValueError(f"field {field!r} of {self.name} is not a WGSL identifier")
            if kind not in WGSL_TYPES:
                raise ValueError(f"field {field!r} of {self.name} must be one of {', '.join(WGSL_TYPES)} (got {kind!r})")

    # --- the layout ---------------------------------------------------------------------------

    @cached_property
    def members(self) -> tuple[Member, ...]:
        """The fields with their offsets: each at the next multiple of its alignment."""
        placed, end = [], 0
        for name, kind in self.fields:
            offset = _round_up(end, WGSL_TYPES[kind][2])
            placed.append(Member(name, kind, offset))
            end = offset + WGSL_TYPES[kind][3]
        return tuple(placed)

    @property
    def offsets(self) -> dict[str, int]:
        """Byte offset of every field, by name."""
        return {m.name: m.offset for m in self.members}

    @property
    def align(self) -> int:
        """WGSL's AlignOf: the largest alignment of a field."""
        return max(m.align for m in self.members)

    @property
    def size(self) -> int:
        """WGSL's SizeOf: the end of the last field rounded up to :attr:`align` (an array's stride)."""
        last = self.members[-1]
        return _round_up(last.offset + last.size, self.align)

    @property
    def buffer_size(self) -> int:
        """Bytes of one value in a buffer: :attr:`size` rounded up to 16 (a uniform buffer's rule)."""
        return _round_up(self.size, UNIFORM_ALIGN)

    @property
    def padding(self) -> int:
        """Bytes of :attr:`buffer_size` that no field covers."""
        return self.buffer_size - sum(m.size for m in self.members)

    @cached_property
    def dtype(self) -> np.dtype:
        """NumPy dtype whose bytes match the WGSL struct (:attr:`buffer_size` long); a vector field is a subarray."""
        return np.dtype(
            {
                "names": [m.name for m in self.members],
                "formats": [
                    _SCALARS[m.scalar][0] if m.components == 1 else (_SCALARS[m.scalar][0], (m.components,))
                    for m in self.members
                ],
                "offsets": [m.offset for m in self.members],
                "itemsize": self.buffer_size,
            }
        )

    # --- WGSL text -----------------------------------------------------------------------------

    def wgsl(self) -> str:
        """The WGSL declaration of the struct, each field's offset in a comment.

        WGSL lays the fields out itself by the same rules, so the declaration
        needs no ``@align`` or ``@size``; the comments say where each field lies.
        """
        width = max(len(f"{m.name}: {m.kind},") for m in self.members)
        body = "\n".join(f"    {f'{m.name}: {m.kind},':<{width}}  // offset {m.offset}" for m in self.members)
        return f"struct {self.name} {{  // {self.buffer_size} bytes, generated by bokehfit.gpu.layout\n{body}\n}}\n"

    def check_wgsl(self, source: str) -> None:
        """Check that the WGSL ``source`` declares this struct with the same fields and types, in order.

        Raises
        ------
        ValueError
            If ``source`` declares no struct of this name, or one whose fields
            differ (named), or gives a field ``@align``/``@size`` (the offsets would
            no longer be WGSL's own).
        """
        code = re.sub(r"//[^\n]*", "", source)
        found = re.search(rf"\bstruct\s+{re.escape(self.name)}\s*\{{([^}}]*)\}}", code)
        if found is None:
            raise ValueError(f"the WGSL declares no struct {self.name}")
        declared = []
        for item in (p.strip() for p in found.group(1).split(",")):
            if not item:
                continue
            if "@" in item:
                raise ValueError(f"{self.name}: {item!r} has an attribute; the layout must be WGSL's own")
            name, _, kind = (s.strip() for s in item.partition(":"))
            declared.append((name, _LONG_VECTOR.sub(lambda m: f"vec{m.group(1)}{m.group(2)[0]}", kind.replace(" ", ""))))
        if tuple(declared) != self.fields:
            expected = [f"{n}: {k}" for n, k in self.fields]
            got = [f"{n}: {k}" for n, k in declared]
            raise ValueError(f"the WGSL's struct {self.name} differs from its layout: declared {got}, layout {expected}")

    def wgsl_record(self, record) -> str:
        """A WGSL constructor expression of one record of :attr:`dtype`, e.g. ``Params(1u, vec2f(0.5f, 2.0f))``."""

        def literal(scalar: str, value) -> str:
            if scalar == "f32":
                return f"{float(value)!r}f"
            return f"{int(value)}{_SCALARS[scalar][1]}"

        args = []
        for m in self.members:
            value = record[m.name]
            if m.components == 1:
                args.append(literal(m.scalar, value))
            else:
                args.append(f"{m.kind}(" + ", ".join(literal(m.scalar, v) for v in value) + ")")
        return f"{self.name}({', '.join(args)})"

    def wgsl_value(self, **values) -> str:
        """A WGSL constructor expression of one struct value, e.g. ``Params(1u, 0.5f)``; every field must be given.

        For shader code generated around a value (tests, constant parameters);
        buffers take :meth:`pack`.
        """
        return self.wgsl_record(self.record(**values))

    # --- values -------------------------------------------------------------------------------

    def record(self, **values) -> np.void:
        """One record of :attr:`dtype`; every field must be given, a vector field as a sequence of its components."""
        missing = set(self.offsets) - set(values)
        extra = set(values) - set(self.offsets)
        if missing or extra:
            raise ValueError(f"{self.name}: missing fields {sorted(missing)}, unknown fields {sorted(extra)}")
        record = np.zeros((), dtype=self.dtype)
        for m in self.members:
            value = values[m.name]
            if m.components > 1 and np.shape(value) != (m.components,):
                raise ValueError(f"{self.name}.{m.name} is a {m.kind}: give {m.components} values (got {value!r})")
            record[m.name] = value
        return record[()]

    def pack(self, **values) -> bytes:
        """Bytes of one struct value (:attr:`buffer_size` long); every field must be given."""
        return self.record(**values).tobytes()

    def layout_json(self) -> dict:
        """The layout for a packer outside Python (the viewer's page): fields with offsets, size, declaration."""
        return {
            "name": self.name,
            "fields": [
                {"name": m.name, "type": m.kind, "scalar": m.scalar, "components": m.components, "offset": m.offset}
                for m in self.members
            ],
            "size_bytes": self.buffer_size,
            "wgsl": self.wgsl(),
        }
