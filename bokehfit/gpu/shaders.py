"""Load WGSL from the installed package, resolving ``// #include "name"`` lines.

An include names either a file of ``bokehfit.shaders`` (``rng.wgsl``) or a
generated source (a struct from :mod:`bokehfit.gpu.layout`, the shape ids of
the aperture registry) passed in ``generated``. Each is included once, however
many files ask for it, so shared code is never pasted twice.
"""

from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources

from bokehfit.apertures import SHADER_FAMILIES

__all__ = ["load_shader", "shader_source", "shape_ids_wgsl"]

_INCLUDE = re.compile(r'^\s*//\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


@lru_cache(maxsize=None)
def shader_source(filename: str) -> str:
    """Raw text of ``shaders/<filename>`` from the installed package."""
    path = resources.files("bokehfit.shaders").joinpath(filename)
    if not path.is_file():
        raise FileNotFoundError(f"shader {filename!r} is missing from the bokehfit package (reinstall it)")
    return path.read_text(encoding="utf-8")


def shape_ids_wgsl() -> str:
    """``const SHAPE_<FAMILY>: u32`` lines, generated from the aperture registry."""
    return "".join(f"const SHAPE_{family.upper()}: u32 = {i}u;\n" for i, family in enumerate(SHADER_FAMILIES))


def load_shader(filename: str, generated: dict[str, str] | None = None) -> str:
    """WGSL of ``filename`` with every include resolved (each at most once).

    ``generated`` maps include names to source text; ``shape_ids`` is always there.
    """
    sources = {"shape_ids": shape_ids_wgsl(), **(generated or {})}
    seen: set[str] = set()

    def expand(name: str) -> str:
        if name in seen:
            return ""
        seen.add(name)
        text = sources[name] if name in sources else shader_source(name)
        return _INCLUDE.sub(lambda m: expand(m.group(1)), text)

    return expand(filename)
