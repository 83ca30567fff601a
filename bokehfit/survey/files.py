"""Which files a survey looks at: folders walked, glob patterns, file lists; and their content hash."""

from __future__ import annotations

import glob
import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

from bokehfit.errors import InputError
from bokehfit.io.photo import RAW_SUFFIXES

__all__ = ["PHOTO_SUFFIXES", "find_photos", "read_file_list", "content_hash"]

#: Suffixes (lower case) that a folder walk or a glob picks up: JPEG, PNG, TIFF and camera raw.
PHOTO_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"}) | RAW_SUFFIXES

_GLOB_CHARACTERS = frozenset("*?[")


def _is_photo(path: Path) -> bool:
    return path.suffix.lower() in PHOTO_SUFFIXES and not path.name.startswith(".")


def read_file_list(source: str | os.PathLike) -> list[str]:
    """The paths listed in a text file, one a line (blank lines and ``#`` comments skipped).

    Relative paths are taken from the list's own folder.
    """
    source = Path(source)
    try:
        text = source.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"--files-from must be a readable UTF-8 text file of paths (got {str(source)!r}: {error})") from None
    lines = (line.strip() for line in text.splitlines())
    return [str(source.parent / line) for line in lines if line and not line.startswith("#")]


def find_photos(paths: Iterable[str | os.PathLike]) -> list[Path]:
    """The photo files that ``paths`` name, each once, in a stable order.

    Parameters
    ----------
    paths : iterable of str or path-like
        Each is a file (taken whatever its suffix), a folder (walked, every
        file with a suffix of :data:`PHOTO_SUFFIXES`, hidden files left out) or
        a glob pattern (``**`` crosses folders; matches filtered as for folders).

    Raises
    ------
    InputError
        Naming a path that is neither a file, a folder nor a pattern that matches anything.
    """
    found: dict[Path, None] = {}
    for given in paths:
        text = str(given)
        path = Path(text)
        if path.is_file():
            found[path] = None
        elif path.is_dir():
            for folder, folders, names in os.walk(path):
                folders[:] = sorted(name for name in folders if not name.startswith("."))
                for name in sorted(names):
                    if _is_photo(Path(name)):
                        found[Path(folder) / name] = None
        elif _GLOB_CHARACTERS & set(text):
            matches = [Path(m) for m in sorted(glob.glob(text, recursive=True))]
            photos = [m for m in matches if m.is_file() and _is_photo(m)]
            if not photos:
                raise InputError(f"PATH pattern {text!r} matches no photo ({', '.join(sorted(PHOTO_SUFFIXES)[:5])}, ...)")
            found.update(dict.fromkeys(photos))
        else:
            raise InputError(f"PATH {text!r} is not a file, a folder or a glob pattern that matches photos")
    return list(found)


def content_hash(path: str | os.PathLike) -> str:
    """SHA-256 of the file's bytes, as 64 hex digits: a photo's key in the survey database."""
    with open(path, "rb") as file:
        return hashlib.file_digest(file, "sha256").hexdigest()
