"""Load WGSL from the package, resolving ``// #include "name"`` lines.

An include names either a file of ``bokehfit.shaders`` (``rng.wgsl``) or a
generated source (a struct from :mod:`bokehfit.gpu.layout`, the shape ids of
the aperture registry) passed in ``generated``. Each is included once, however
many files ask for it, so shared code is never pasted twice.

The WGSL files live in the repository's top-level ``shaders/`` folder, which
the wheel (and an editable install) maps to the package ``bokehfit.shaders``.
:func:`shader_dir` is the one place that finds them: when ``bokehfit`` was
imported from a source checkout (Python started in the repository root finds
the checkout's ``bokehfit/`` before the installed wheel, and the checkout has
no ``bokehfit/shaders/``), the checkout's own ``shaders/`` folder; otherwise
the package ``bokehfit.shaders``. There are no copies.
"""

from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

import bokehfit
from bokehfit.apertures import APERTURE_PARAM_FIELDS, CHANNELS, SHADER_FAMILIES
from bokehfit.gpu.compute import Binding
from bokehfit.gpu.layout import Struct

if TYPE_CHECKING:  # importlib.resources.abc is Python 3.11+
    from importlib.resources.abc import Traversable

__all__ = [
    "APERTURE_PARAMS",
    "MASK_TABLE_BINDING",
    "MASK_TABLE_READ",
    "MASK_TABLE_STUB",
    "load_shader",
    "mask_table_data",
    "mask_table_wgsl",
    "shader_dir",
    "shader_source",
    "shape_ids_wgsl",
]

_INCLUDE = re.compile(r'^\s*//\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)

#: The WGSL ``ApertureParams`` of ``sample_aperture_params`` (apertures.wgsl), from the one
#: description in the aperture model; fill it from ``Aperture.shader_params()``.
APERTURE_PARAMS = Struct("ApertureParams", APERTURE_PARAM_FIELDS)

#: The include ``mask_table`` of shaders that bind no mask table (the test harnesses of single
#: samplers): apertures.wgsl compiles there, and a mask aperture is not drawn by them.
MASK_TABLE_STUB = "fn mask_table_value(i: u32) -> f32 { return 0.0; }\n"


#: The include ``mask_table`` of a shader whose :class:`~bokehfit.gpu.compute.ComputeInterface`
#: declares the binding ``mask_table: array<f32>`` (:data:`MASK_TABLE_BINDING`) itself.
MASK_TABLE_READ = "fn mask_table_value(i: u32) -> f32 { return mask_table[i]; }\n"

#: The binding of a mask's CDF tables in the interface of every shader that samples the lens's
#: aperture (kernel_mc, pathtrace, points); its buffer holds :func:`mask_table_data`.
MASK_TABLE_BINDING = Binding("mask_table", "storage, read", "array<f32>")


def mask_table_data(aperture) -> np.ndarray:
    """The float32 contents of :data:`MASK_TABLE_BINDING` for ``aperture``.

    A mask's CDF tables (``MaskTable.gpu_table``, read by WGSL ``sample_mask``);
    a single 0 where the aperture is no mask, since the binding must exist.
    """
    return aperture.mask.gpu_table() if aperture.mask is not None else np.zeros(1, dtype=np.float32)


def mask_table_wgsl(binding: int, group: int = 0) -> str:
    """The include ``mask_table`` of a shader that binds a mask's CDF tables (``MaskTable.gpu_table``) at ``binding``."""
    return (
        f"@group({group}) @binding({binding}) var<storage, read> mask_table: array<f32>;\n"
        "fn mask_table_value(i: u32) -> f32 { return mask_table[i]; }\n"
    )


#: The package the wheel builds from the top-level ``shaders/`` folder (pyproject.toml).
SHADER_PACKAGE = "bokehfit.shaders"


@lru_cache(maxsize=1)
def shader_dir() -> Traversable:
    """The folder of the WGSL sources that belong to the imported ``bokehfit``.

    Returns
    -------
    Traversable
        The ``shaders/`` folder beside the imported ``bokehfit/`` folder when that is
        a source checkout (``pyproject.toml`` beside it too), else
        ``importlib.resources.files("bokehfit.shaders")`` (an installed wheel).

    Raises
    ------
    FileNotFoundError
        If neither exists: a broken install.
    """
    package = Path(bokehfit.__file__).resolve().parent
    checkout = package.parent
    if (checkout / "pyproject.toml").is_file() and (checkout / "shaders" / "__init__.py").is_file():
        return checkout / "shaders"
    try:
        return resources.files(SHADER_PACKAGE)
    except ModuleNotFoundError as error:
        if error.name != SHADER_PACKAGE:
            raise
    raise FileNotFoundError(
        f"the WGSL shaders are missing: no package {SHADER_PACKAGE} beside {package} and no source checkout "
        "(reinstall bokehfit)"
    )


@lru_cache(maxsize=None)
def shader_source(filename: str) -> str:
    """Raw text of ``shaders/<filename>``, from the folder :func:`shader_dir` finds."""
    path = shader_dir().joinpath(filename)
    if not path.is_file():
        raise FileNotFoundError(f"shader {filename!r} is missing from the bokehfit package (reinstall it)")
    return path.read_text(encoding="utf-8")


def shape_ids_wgsl() -> str:
    """What apertures.wgsl needs from the aperture model, generated from it.

    ``const SHAPE_<FAMILY>: u32`` (the sampler families of the registry),
    ``const CHANNEL_<NAME>: u32`` (the colour channels) and the
    ``ApertureParams`` struct.
    """
    shapes = "".join(f"const SHAPE_{family.upper()}: u32 = {i}u;\n" for i, family in enumerate(SHADER_FAMILIES))
    channels = "".join(f"const CHANNEL_{name.upper()}: u32 = {i}u;\n" for i, name in enumerate(CHANNELS))
    return shapes + channels + APERTURE_PARAMS.wgsl()


def load_shader(filename: str, generated: dict[str, str] | None = None) -> str:
    """WGSL of ``filename`` with every include resolved (each at most once).

    ``generated`` maps include names to source text; ``shape_ids`` is always there, and
    ``mask_table`` is :data:`MASK_TABLE_STUB` unless given (:func:`mask_table_wgsl`).
    """
    sources = {"shape_ids": shape_ids_wgsl(), "mask_table": MASK_TABLE_STUB, **(generated or {})}
    seen: set[str] = set()

    def expand(name: str) -> str:
        if name in seen:
            return ""
        seen.add(name)
        text = sources[name] if name in sources else shader_source(name)
        return _INCLUDE.sub(lambda m: expand(m.group(1)), text)

    return expand(filename)
