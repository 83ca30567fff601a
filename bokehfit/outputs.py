"""Write result files atomically, and refuse to write over an input.

Every output goes to a temporary file in the destination's folder and is then
renamed over the destination, so a reader never sees half a file and a crash
never leaves one behind.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from bokehfit.errors import InputError

__all__ = [
    "check_output_path",
    "write_atomic",
    "write_bytes_atomic",
    "write_json",
    "write_png",
    "write_kernel_image",
    "KERNEL_FORMATS",
]

#: Kernel file formats by suffix.
KERNEL_FORMATS = (".npy", ".png", ".exr")


def check_output_path(path: str | os.PathLike, suffixes: Iterable[str], inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """``path`` as a Path, or ``InputError`` if it can't be written or names an input."""
    path = Path(path)
    suffixes = tuple(suffixes)
    if path.suffix.lower() not in suffixes:
        raise InputError(f"output file must end in {', '.join(suffixes)} (got {str(path)!r})")
    if not path.parent.is_dir():
        raise InputError(f"output folder {str(path.parent)!r} does not exist")
    if path.is_dir():
        raise InputError(f"output {str(path)!r} is a folder")
    for source in inputs:
        if Path(source).exists() and path.exists() and path.samefile(source):
            raise InputError(f"output {str(path)!r} would overwrite the input; choose another name")
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    """Call ``write(temporary_path)``, then rename the temporary file to ``path``."""
    fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    os.chmod(temporary, 0o666 & ~_umask())  # mkstemp makes it private; outputs get the usual mode
    try:
        write(Path(temporary))
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    write_atomic(path, lambda tmp: tmp.write_bytes(data))


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as indented JSON, atomically."""
    write_bytes_atomic(path, (json.dumps(data, indent=1, allow_nan=False) + "\n").encode("utf-8"))


def write_png(path: Path, image: np.ndarray) -> None:
    """Write an 8- or 16-bit image (grey, or BGR as OpenCV orders it) as PNG, atomically."""
    import cv2

    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"could not encode {path} as PNG")
    write_bytes_atomic(path, encoded.tobytes())


def write_kernel_image(path: Path, kernel: np.ndarray) -> None:
    """Save a kernel: ``.npy`` raw float32, ``.png`` 16-bit scaled to its peak, ``.exr`` float32."""
    suffix = path.suffix.lower()
    if suffix == ".npy":
        write_atomic(path, lambda tmp: np.save(tmp, kernel.astype(np.float32)))
    elif suffix == ".png":
        peak = float(kernel.max())
        scaled = np.round(kernel / peak * 65535.0) if peak > 0 else np.zeros_like(kernel)
        write_png(path, scaled.astype(np.uint16))
    elif suffix == ".exr":
        import OpenEXR

        def write(tmp: Path) -> None:
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            with OpenEXR.File(header, {"Y": np.ascontiguousarray(kernel, dtype=np.float32)}) as exr:
                exr.write(str(tmp))

        write_atomic(path, write)
    else:
        raise InputError(f"kernel file must end in {', '.join(KERNEL_FORMATS)} (got {str(path)!r})")
