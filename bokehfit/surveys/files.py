"""Which files a survey looks at: folders walked, glob patterns, file lists; and their content hash.

Every input here is bounded: a list is read only if it is a regular file, up to
:data:`LIST_MAX_BYTES`; a walk (a folder or a glob pattern) visits each folder
once, however symbolic links loop, and stops with an error past
:data:`WALK_MAX_ENTRIES` entries; a photo is hashed only if it is a regular file
(a FIFO or a link to ``/dev/zero`` named ``*.jpg`` becomes an ``unreadable``
row with the reason, never a read that waits or never ends).
"""

from __future__ import annotations

import fnmatch
import hashlib
import os
import stat
from collections.abc import Iterable
from pathlib import Path

from bokehfit.errors import InputError
from bokehfit.io.photo import RAW_SUFFIXES
from bokehfit.regular_files import open_regular

__all__ = ["PHOTO_SUFFIXES", "LIST_MAX_BYTES", "WALK_MAX_ENTRIES", "find_photos", "read_file_list", "content_hash"]

#: Suffixes (lower case) that a folder walk or a glob picks up: JPEG, PNG, TIFF and camera raw.
PHOTO_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".tif", ".tiff"}) | RAW_SUFFIXES
#: Largest ``--files-from`` list read: a million paths of 250 bytes (a library far larger than any survey runs).
LIST_MAX_BYTES = 256 << 20
#: Most entries (files and folders) one folder walk or glob pattern visits before it stops with an error:
#: ten million, about ten times the largest photo libraries; a few minutes of walking at most.
WALK_MAX_ENTRIES = 10_000_000

_GLOB_CHARACTERS = frozenset("*?[")


def _is_photo(path: Path) -> bool:
    return path.suffix.lower() in PHOTO_SUFFIXES and not path.name.startswith(".")


def read_file_list(source: str | os.PathLike) -> list[str]:
    """The paths listed in a text file, one a line (blank lines and ``#`` comments skipped).

    Relative paths are taken from the list's own folder. The list must be a regular file
    of at most :data:`LIST_MAX_BYTES` (a FIFO or a device is refused before it is read).
    """
    source = Path(source)
    problem = f"--files-from must be a readable UTF-8 text file of paths (got {str(source)!r}"
    try:
        with open_regular(source) as file:
            data = file.read(LIST_MAX_BYTES + 1)
        if len(data) > LIST_MAX_BYTES:
            raise InputError(f"{problem}: it is larger than {LIST_MAX_BYTES >> 20} MiB; split it)")
        text = data.decode("utf-8")
    except OSError as error:
        raise InputError(f"{problem}: {error.strerror or error})") from None
    except UnicodeDecodeError as error:
        raise InputError(f"{problem}: {error})") from None
    lines = (line.strip() for line in text.splitlines())
    return [str(source.parent / line) for line in lines if line and not line.startswith("#")]


class _Walk:
    """A bounded walk: each folder visited once (by device and inode), at most :data:`WALK_MAX_ENTRIES` entries."""

    def __init__(self, what: str):
        self.what, self.entries, self.seen = what, 0, set()

    def folders(self, top: Path, follow_links: bool, enter=None):
        """(folder, sorted sub-folder names, sorted file names) from ``top`` down, hidden sub-folders left out.

        ``enter(folder)``, where given, says whether a sub-folder is walked at all.
        """
        pending = [top]
        while pending:
            folder = pending.pop()
            try:
                info = os.stat(folder) if follow_links else os.lstat(folder)
                with os.scandir(folder) as scan:
                    entries = list(scan)
            except OSError:
                continue
            if (info.st_dev, info.st_ino) in self.seen:  # a symbolic link back up the tree
                continue
            self.seen.add((info.st_dev, info.st_ino))
            self.entries += len(entries)
            if self.entries > WALK_MAX_ENTRIES:
                raise InputError(f"{self.what} reaches more than {WALK_MAX_ENTRIES:,} files and folders; name fewer")
            folders = sorted(e.name for e in entries if not e.name.startswith(".") and _is_folder(e, follow_links))
            files = sorted(e.name for e in entries if not _is_folder(e, follow_links))
            yield folder, folders, files
            pending.extend(folder / name for name in reversed(folders) if enter is None or enter(folder / name))


def _is_folder(entry: os.DirEntry, follow_links: bool) -> bool:
    try:
        return entry.is_dir(follow_symlinks=follow_links)
    except OSError:
        return False


def _glob(pattern: str) -> list[Path]:
    """The files that ``pattern`` matches (``**`` any folders, links to folders followed), each folder visited once.

    Unlike :func:`glob.glob`, a symbolic link that loops (``a/loop -> ..``) is entered once,
    and the walk stops with an error past :data:`WALK_MAX_ENTRIES` entries. Names are matched
    one by one with :func:`fnmatch.fnmatchcase`; as for :mod:`glob`, a name that starts with
    ``.`` is matched only by a pattern part that does too.
    """
    parts = Path(pattern).parts
    fixed = next((i for i, part in enumerate(parts) if _GLOB_CHARACTERS & set(part)), len(parts))
    root = Path(*parts[:fixed]) if fixed else Path()
    rest = parts[fixed:]
    if not rest:
        return [root] if root.is_file() else []
    deep = "**" in rest

    def enter(folder: Path) -> bool:  # only folders that files matching the pattern can be in
        relative = folder.parts[len(root.parts):]
        return (deep or len(relative) < len(rest)) and _prefix_matches(rest, relative)

    found = []
    for folder, _, files in _Walk(f"PATH pattern {pattern!r}").folders(root, follow_links=True, enter=enter):
        relative = folder.parts[len(root.parts):]
        found.extend(folder / name for name in files if _matches(rest, (*relative, name)))
    return sorted(found)


def _name_matches(part: str, name: str) -> bool:
    return (part.startswith(".") or not name.startswith(".")) and fnmatch.fnmatchcase(name, part)


def _matches(pattern: tuple[str, ...], names: tuple[str, ...]) -> bool:
    """Whether the path ``names`` matches ``pattern`` part by part (``**``: zero or more names; last: one or more)."""
    if not pattern:
        return not names
    if pattern[0] == "**":
        if len(pattern) == 1:
            return bool(names) and not any(name.startswith(".") for name in names)
        return any(_matches(pattern[1:], names[i:]) for i in range(len(names) + 1)
                   if not any(name.startswith(".") for name in names[:i]))
    return bool(names) and _name_matches(pattern[0], names[0]) and _matches(pattern[1:], names[1:])


def _prefix_matches(pattern: tuple[str, ...], folders: tuple[str, ...]) -> bool:
    """Whether files under the folder ``folders`` may still match ``pattern`` (prunes nothing after ``**``)."""
    for i, name in enumerate(folders):
        if i >= len(pattern) or pattern[i] == "**":
            return i < len(pattern)
        if not _name_matches(pattern[i], name):
            return False
    return True


def find_photos(paths: Iterable[str | os.PathLike]) -> list[Path]:
    """The photo files that ``paths`` name, each once, in a stable order.

    Parameters
    ----------
    paths : iterable of str or path-like
        Each is a file (taken whatever its suffix), a folder (walked, every
        file with a suffix of :data:`PHOTO_SUFFIXES`, hidden files left out) or
        a glob pattern (``**`` crosses folders; matches filtered as for folders).
        Entries that are not regular files (FIFOs, devices, links to them) are kept:
        the survey records each as ``unreadable`` with the reason, without reading it.

    Raises
    ------
    InputError
        Naming a path that is neither a file, a folder nor a pattern that matches anything,
        or a walk past :data:`WALK_MAX_ENTRIES` entries.
    """
    found: dict[Path, None] = {}
    for given in paths:
        text = str(given)
        path = Path(text)
        try:
            mode = os.stat(path).st_mode
        except (OSError, ValueError):
            mode = None
        if mode is not None and stat.S_ISDIR(mode):
            for folder, _, names in _Walk(f"PATH {text!r}").folders(path, follow_links=False):
                for name in names:
                    if _is_photo(Path(name)):
                        found[folder / name] = None
        elif mode is not None:
            found[path] = None  # a file, or a FIFO or device named on purpose: an unreadable row says why
        elif _GLOB_CHARACTERS & set(text):
            photos = [m for m in _glob(text) if _is_photo(m)]
            if not photos:
                raise InputError(f"PATH pattern {text!r} matches no photo ({', '.join(sorted(PHOTO_SUFFIXES)[:5])}, ...)")
            found.update(dict.fromkeys(photos))
        else:
            raise InputError(f"PATH {text!r} is not a file, a folder or a glob pattern that matches photos")
    return list(found)


def content_hash(path: str | os.PathLike) -> str:
    """SHA-256 of the file's bytes, as 64 hex digits: a photo's key in the survey database.

    Raises ``OSError`` (its reason in words) for anything that is not a regular file, without reading it.
    """
    with open_regular(path) as file:
        return hashlib.file_digest(file, "sha256").hexdigest()
