"""Pick a WebGPU adapter through wgpu-py and open one device for the process.

The choice, in order: ``BOKEHFIT_ADAPTER`` (a case-insensitive part of the
adapter's name, e.g. ``llvmpipe`` or ``H100``) and ``BOKEHFIT_BACKEND``
(``vulkan``, ``metal``, ``d3d12`` or ``gl``) narrow the list of adapters; among
what is left a discrete GPU wins over an integrated one, over a CPU adapter.
Unless ``BOKEHFIT_BACKEND=gl`` asks for it, only the primary backends (Vulkan,
Metal, D3D12) are opened: OpenGL through wgpu is a last resort, and probing it
needs a display. With no adapter at all the error names the Debian packages
that give Mesa's lavapipe, a software Vulkan adapter.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from functools import lru_cache

from bokehfit.errors import GPUUnavailableError

__all__ = ["GPUContext", "get_gpu", "use_headless_egl", "ADAPTER_ENV", "BACKEND_ENV"]

ADAPTER_ENV = "BOKEHFIT_ADAPTER"
BACKEND_ENV = "BOKEHFIT_BACKEND"
#: BOKEHFIT_BACKEND value → (wgpu-native instance backend, adapter backend_type).
_BACKENDS = {"vulkan": ("Vulkan", "Vulkan"), "metal": ("Metal", "Metal"), "d3d12": ("DX12", "D3D12"), "gl": ("GL", "OpenGL")}
_TYPE_RANK = {"DiscreteGPU": 0, "IntegratedGPU": 1, "VirtualGPU": 2, "CPU": 3}
NO_ADAPTER_FIX = (
    "install a Vulkan driver; on Debian or Ubuntu `apt-get install libvulkan1 mesa-vulkan-drivers` "
    "gives the lavapipe CPU adapter"
)


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
    """
    os.environ.setdefault("EGL_PLATFORM", "surfaceless")
    if not os.environ.get("XDG_RUNTIME_DIR"):
        # One private, empty folder per user, reused by every process (nothing is left behind).
        folder = os.path.join(tempfile.gettempdir(), f"bokehfit-runtime-{os.getuid()}")
        os.makedirs(folder, mode=0o700, exist_ok=True)
        os.environ["XDG_RUNTIME_DIR"] = folder


def _rank(info) -> int:
    return _TYPE_RANK.get(info["adapter_type"], 4)


@lru_cache(maxsize=1)
def get_gpu() -> GPUContext:
    """The process's one GPU context, opened on first use.

    Raises
    ------
    GPUUnavailableError
        When wgpu cannot load, no adapter matches, or the device won't open.
    """
    want_name = os.environ.get(ADAPTER_ENV, "").strip().lower()
    want_backend = os.environ.get(BACKEND_ENV, "").strip().lower()
    if want_backend and want_backend not in _BACKENDS:
        raise GPUUnavailableError(f"{BACKEND_ENV} must be one of {', '.join(_BACKENDS)} (got {want_backend!r})")
    use_headless_egl()
    try:
        import wgpu
        from wgpu.backends.wgpu_native.extras import set_instance_extras
    except (ImportError, OSError) as error:  # the wgpu-native library failed to load
        raise GPUUnavailableError(f"cannot load wgpu ({error}); reinstall bokehfit") from None

    try:
        set_instance_extras(backends=[_BACKENDS[want_backend][0] if want_backend else "Primary"])
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
        wanted = " and ".join(
            s for s in (want_name and f"{ADAPTER_ENV}={want_name!r}", want_backend and f"{BACKEND_ENV}={want_backend!r}") if s
        )
        raise GPUUnavailableError(f"no WebGPU adapter matches {wanted}; found: {', '.join(found)}")
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
