"""bokehfit's temporary files: their names, and the removal of those that killed processes left behind.

An output is first written to a temporary file in the destination's folder
(:func:`new_temporary`), named ``.NAME.bokehfit-tmp-PID-TOKEN.SUFFIX``, and then renamed
over the destination (:func:`bokehfit.outputs.write_atomic`, which removes its own if the
write fails). One left by a process that was killed outright (SIGKILL, a crash, a power
cut) is removed by the next run that checks an output in that folder
(:func:`bokehfit.output_paths.check_output_path`, before any work) or writes there
(:func:`remove_stale_temporaries`), once no process with that PID is running, or the
process now holding that PID started after the file was last written (Linux; the PID was
reused). Elsewhere than POSIX systems they are left alone.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
from pathlib import Path

__all__ = ["new_temporary", "remove_stale_temporaries"]

#: The name of a temporary file (:func:`new_temporary`), with the number (PID) of the process that made it.
_TEMPORARY = re.compile(r"^\..+\.bokehfit-tmp-(?P<pid>\d+)-[0-9a-f]+(\.[^.]*)?$")


def _process_running(pid: int) -> bool:
    """Whether a process ``pid`` may be running (True where that can't be told)."""
    if pid == os.getpid() or os.name != "posix":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, ValueError):  # no process can have that number
        return False
    return True


def _process_started_at(pid: int) -> float | None:
    """When process ``pid`` started (seconds since the epoch), where the system says (Linux); else None."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as file:
            fields = file.read().rsplit(b")", 1)[1].split()
        with open("/proc/stat", "rb") as file:
            boot = next(float(line.split()[1]) for line in file if line.startswith(b"btime "))
        return boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22 of stat: start time in clock ticks
    except (OSError, ValueError, IndexError, StopIteration):
        return None


#: Slack (seconds) when comparing a process's start with a file's time: /proc/stat's boot time is whole seconds.
_CLOCK_SLACK_S = 2.0


def _temporary_is_stale(path: str, pid: int) -> bool:
    """Whether the temporary file ``path`` named for process ``pid`` belongs to no running process.

    It does when no process ``pid`` runs, or when the process now called ``pid`` started after
    the file was last written (the writer was killed and its number given to another process).
    """
    if not _process_running(pid):
        return True
    if pid == os.getpid():
        return False
    started = _process_started_at(pid)
    try:
        written = os.lstat(path).st_mtime
    except OSError:
        return False
    return started is not None and started > written + _CLOCK_SLACK_S


def remove_stale_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove the temporary files that killed bokehfit processes left in ``folder``; returns them.

    Only files of bokehfit's own naming (``.NAME.bokehfit-tmp-PID-TOKEN.SUFFIX``) that are
    regular files and belong to no running process (:func:`_temporary_is_stale`) are removed.
    """
    removed = []
    try:
        with os.scandir(folder) as scan:
            entries = [entry for entry, _ in zip(scan, range(_SCAN_MAX_ENTRIES))]
    except OSError:
        return removed
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        if match and entry.is_file(follow_symlinks=False) and _temporary_is_stale(entry.path, int(match["pid"])):
            with contextlib.suppress(OSError):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
    return removed


#: Most entries of one folder looked at for stale temporary files (a folder of a million files is not scanned whole).
_SCAN_MAX_ENTRIES = 100_000


def new_temporary(path: Path) -> Path:
    """Create an empty temporary file for ``path`` in its folder (usual permissions: 0o666 less the umask)."""
    for _ in range(16):
        temporary = path.parent / f".{path.name[:180]}.bokehfit-tmp-{os.getpid()}-{secrets.token_hex(4)}{path.suffix}"
        try:
            os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return temporary
        except FileExistsError:
            continue
    raise OSError(f"could not create a temporary file beside {path}")
