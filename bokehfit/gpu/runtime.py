"""Pick a WebGPU adapter through wgpu-py and open a device on it.

The choice is an argument, an :class:`AdapterChoice`: a case-insensitive part
of the adapter's name (e.g. ``llvmpipe`` or ``H100``) and a backend
(``vulkan``, ``metal``, ``d3d12`` or ``gl``) narrow the list of adapters; among
what is left a discrete GPU wins over an integrated one, over a CPU adapter.
Unless the backend ``gl`` is asked for, only the primary backends (Vulkan,
Metal, D3D12) are opened: OpenGL through wgpu is a last resort, and probing it
needs a display. With no adapter at all the error names the Debian packages
that give Mesa's lavapipe, a software Vulkan adapter.

Nothing here reads the environment to choose: the command line turns
``BOKEHFIT_ADAPTER`` and ``BOKEHFIT_BACKEND`` into an :class:`AdapterChoice`
(:func:`bokehfit.cli.adapter_from_environment`) and passes it down.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import shutil
import stat
import tempfile
from dataclasses import dataclass
from functools import lru_cache

from bokehfit.errors import GPUUnavailableError, InputError

__all__ = ["AdapterChoice", "BACKENDS", "GPUContext", "get_gpu", "use_headless_egl"]

#: Backend name → (wgpu-native instance backend, adapter backend_type).
_BACKENDS = {"vulkan": ("Vulkan", "Vulkan"), "metal": ("Metal", "Metal"), "d3d12": ("DX12", "D3D12"), "gl": ("GL", "OpenGL")}
#: The backends an :class:`AdapterChoice` may name.
BACKENDS = tuple(_BACKENDS)
_TYPE_RANK = {"DiscreteGPU": 0, "IntegratedGPU": 1, "VirtualGPU": 2, "CPU": 3}
NO_ADAPTER_FIX = (
    "install a Vulkan driver; on Debian or Ubuntu `apt-get install libvulkan1 mesa-vulkan-drivers` "
    "gives the lavapipe CPU adapter"
)


@dataclass(frozen=True)
class AdapterChoice:
    """Which WebGPU adapter to open; the defaults take the best one found.

    Parameters
    ----------
    name : str
        A case-insensitive part of the adapter's name (``llvmpipe`` picks
        Mesa's lavapipe); empty for any adapter.
    backend : str
        One of ``BACKENDS`` (``vulkan``, ``metal``, ``d3d12``, ``gl``),
        case-insensitive; empty for any primary backend.

    Both are stored stripped and lower-case, so equal choices compare and hash
    equal (:func:`get_gpu` keeps one device per choice).

    Raises
    ------
    InputError
        Naming ``name`` or ``backend`` when it is not a string, or ``backend``
        when it is not one of ``BACKENDS``.

    Examples
    --------
    >>> AdapterChoice("LLVMpipe", "Vulkan")
    AdapterChoice(name='llvmpipe', backend='vulkan')
    """

    name: str = ""
    backend: str = ""

    def __post_init__(self):
        for field in ("name", "backend"):
            value = getattr(self, field)
            if not isinstance(value, str):
                raise InputError(f"{field} must be a string (got {type(value).__name__})")
            object.__setattr__(self, field, value.strip().lower())
        if self.backend and self.backend not in _BACKENDS:
            raise InputError(f"backend must be one of {', '.join(BACKENDS)} or empty (got {self.backend!r})")

    def describe(self) -> str:
        """The choice in words, for messages: ``any adapter`` when nothing is asked."""
        parts = [f"name containing {self.name!r}" if self.name else "", f"backend {self.backend}" if self.backend else ""]
        return " and ".join(part for part in parts if part) or "any adapter"


@dataclass(frozen=True)
class GPUContext:
    """An open wgpu device and what it runs on."""

    device: object  #: wgpu.GPUDevice
    adapter_name: str
    backend: str
    adapter_type: str

    @property
    def is_lavapipe(self) -> bool:
        """True on Mesa's software Vulkan adapter (it reports itself as llvmpipe)."""
        return "llvmpipe" in self.adapter_name.lower() and self.backend == "Vulkan"

    def describe(self) -> str:
        return f"{self.adapter_name} ({self.backend})"


def use_headless_egl() -> None:
    """Prepare the process for headless GPU use, with no display server.

    Mesa's EGL is asked for its surfaceless platform. Vulkan and EGL loaders
    probe for a Wayland display and, where ``XDG_RUNTIME_DIR`` is unset (as on
    servers and CI), libwayland prints an error line for each probe; an empty
    private runtime folder makes the probe fail quietly instead.

    A runtime folder is adopted only if it is private (:func:`_is_private_folder`: a
    folder, not a link, owned by this user, closed to others, as the XDG Base Directory
    specification requires). One that another user owns or can write to could hold a
    planted Wayland socket that the GPU start would connect to and block on: it is
    replaced, for this process, by a private one.
    """
    os.environ.setdefault("EGL_PLATFORM", "surfaceless")
    if not hasattr(os, "getuid"):
        return
    given = os.environ.get("XDG_RUNTIME_DIR")
    if given and _is_private_folder(given):
        return
    # One private, empty folder per user, reused by every process (nothing is left behind).
    folder = os.path.join(tempfile.gettempdir(), f"bokehfit-runtime-{os.getuid()}")
    with contextlib.suppress(OSError):
        os.mkdir(folder, 0o700)
    if not _is_private_folder(folder):  # someone else made it first: one of this process's own
        folder = tempfile.mkdtemp(prefix="bokehfit-runtime-")
        atexit.register(shutil.rmtree, folder, True)
    os.environ["XDG_RUNTIME_DIR"] = folder


def _is_private_folder(path: str) -> bool:
    """Whether ``path`` is a folder (not a link) owned by this user that no other user may enter or write."""
    try:
        info = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and not info.st_mode & 0o077


def _rank(info) -> int:
    return _TYPE_RANK.get(info["adapter_type"], 4)


def get_gpu(adapter: AdapterChoice | None = None) -> GPUContext:
    """A GPU context on the adapter that ``adapter`` chooses, opened on first use.

    Parameters
    ----------
    adapter : AdapterChoice, optional
        Which adapter; ``AdapterChoice()`` (the best one found) by default.

    Returns
    -------
    GPUContext
        The same context for equal choices: opening a device takes up to a
        second and holds GPU memory, and compiled pipelines are kept per
        device, so each choice's device is opened once per process and then
        shared. Different choices get different devices, even where both
        pick the same adapter.

    Raises
    ------
    InputError
        When ``adapter`` is not an AdapterChoice.
    GPUUnavailableError
        When wgpu cannot load, no adapter matches, or the device won't open
        (not remembered: a later call tries again).
    """
    if adapter is None:
        adapter = AdapterChoice()
    elif not isinstance(adapter, AdapterChoice):
        raise InputError(f"adapter must be an AdapterChoice (got {type(adapter).__name__})")
    return _open_gpu(adapter)


@lru_cache(maxsize=None)
def _open_gpu(choice: AdapterChoice) -> GPUContext:
    """Open a device on the adapter ``choice`` picks (memoised per choice by ``lru_cache``)."""
    want_name, want_backend = choice.name, choice.backend
    use_headless_egl()
    try:
        import wgpu
        from wgpu.backends.wgpu_native.extras import set_instance_extras
    except (ImportError, OSError) as error:  # the wgpu-native library failed to load
        raise GPUUnavailableError(f"cannot load wgpu ({error}); reinstall bokehfit") from None

    try:
        set_instance_extras(backends=[_BACKENDS[want_backend][0] if want_backend else "Primary"])
    except RuntimeError:
        # wgpu-native makes one instance per process, with the backends of the
        # first choice opened; a later choice picks among its adapters.
        pass
    try:
        adapters = wgpu.gpu.enumerate_adapters_sync()
    except Exception as error:  # wgpu-native raises its own types for driver failures
        raise GPUUnavailableError(f"no WebGPU adapter could be listed ({error}); {NO_ADAPTER_FIX}") from None
    found = [f"{a.info['device']} ({a.info['backend_type']})" for a in adapters]
    candidates = [
        a
        for a in adapters
        if want_name in a.info["device"].lower()
        and (not want_backend or a.info["backend_type"] == _BACKENDS[want_backend][1])
    ]
    if not candidates:
        if not adapters:
            raise GPUUnavailableError(f"no WebGPU adapter found; {NO_ADAPTER_FIX}")
        note = " (this process lists only the backends of the first adapter choice it opened)" if want_backend else ""
        raise GPUUnavailableError(f"no WebGPU adapter matches {choice.describe()}; found: {', '.join(found)}{note}")
    adapter = min(candidates, key=lambda a: _rank(a.info))
    limits = {
        "max-storage-buffer-binding-size": adapter.limits["max-storage-buffer-binding-size"],
        "max-buffer-size": adapter.limits["max-buffer-size"],
    }
    try:
        device = adapter.request_device_sync(required_limits=limits)
    except Exception as error:
        raise GPUUnavailableError(f"cannot open {adapter.info['device']} ({error}); {NO_ADAPTER_FIX}") from None
    info = adapter.info
    return GPUContext(device, info["device"], info["backend_type"], info["adapter_type"])
