"""Output paths: refuse, before any work, an output that can't be written or is another's file.

An existing file is replaced only if it is one of bokehfit's own outputs (it carries
bokehfit's mark: :func:`bokehfit.output_marks.is_bokehfit_output`). A FIFO, a device or
a socket at an output path is refused without being opened. Any other existing file (a
photo, notes, another program's output, a file of another type) is refused:
:func:`check_output_path` and the writers (:func:`check_replaceable`) raise
:class:`~bokehfit.errors.InputError` naming it, and the user moves it or chooses
another name. bokehfit never picks another name by itself.

A missing output folder is made (:func:`make_folder`) only when an output is written
into it, so a run that fails first leaves no folder behind.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from bokehfit.errors import InputError
from bokehfit.output_marks import is_bokehfit_output
from bokehfit.output_temporaries import remove_stale_temporaries
from bokehfit.regular_files import file_kind

__all__ = ["check_output_path", "check_replaceable", "make_folder"]


def check_replaceable(path: str | os.PathLike) -> None:
    """``InputError`` if something that bokehfit did not write is at ``path``; nothing if it is free or ours."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = None  # missing (or a dangling link: refused below, as another's file)
    if mode is not None and stat.S_ISDIR(mode):
        raise InputError(f"output {str(path)!r} is a folder")
    if mode is not None and not stat.S_ISREG(mode):
        raise InputError(f"output {str(path)!r} is {file_kind(mode)}, not a regular file; choose a file name")
    if os.path.lexists(path) and not is_bokehfit_output(path):
        raise InputError(
            f"output {str(path)!r} already exists and was not written by bokehfit; move it away or choose another name"
        )


def check_output_path(
    path: str | os.PathLike, suffixes: Iterable[str], inputs: Iterable[str | os.PathLike] = (), *, folder_may_be_missing: bool = False
) -> Path:
    """``path`` as a Path, or ``InputError`` if it can't be written, names an input or holds a file not ours.

    Nothing is created or opened for writing here: with ``folder_may_be_missing`` a missing
    folder is accepted where it could be made (its nearest existing parent is a folder), and
    the writer makes it (:func:`make_folder`) only when it writes, so a run that fails first
    leaves no folder behind. Stale temporary files of killed bokehfit processes in the
    folder are removed (:func:`remove_stale_temporaries`).
    """
    path = Path(path)
    suffixes = tuple(suffixes)
    if path.suffix.lower() not in suffixes:
        raise InputError(f"output file must end in {', '.join(suffixes)} (got {str(path)!r})")
    if not path.parent.is_dir():
        if not folder_may_be_missing:
            raise InputError(f"output folder {str(path.parent)!r} does not exist")
        _check_folder_can_be_made(path.parent)
        return path
    if path.is_dir():
        raise InputError(f"output {str(path)!r} is a folder")
    for source in inputs:
        if Path(source).exists() and path.exists() and path.samefile(source):
            raise InputError(f"output {str(path)!r} would overwrite the input; choose another name")
    check_replaceable(path)
    remove_stale_temporaries(path.parent)
    return path


def _check_folder_can_be_made(folder: Path) -> None:
    """``InputError`` unless the nearest existing parent of the missing ``folder`` is a folder."""
    parent = folder
    while not os.path.lexists(parent) and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"output folder {str(folder)!r} can't be made: {str(parent)!r} is not a folder")


def make_folder(folder: str | os.PathLike) -> Path:
    """Create an output folder (and its parents) if missing; ``InputError`` if that fails."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"cannot create the output folder {str(folder)!r}: {error.strerror or error}") from None
    return folder
