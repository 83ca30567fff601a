"""The Aperture is the only way an aperture travels (issue 24): no public function of the
kernels or the scene takes the aperture's shape, angle or features as loose parameters.

An aperture is built once (:func:`bokehfit.apertures.make_aperture`, or from command-line
options by :func:`bokehfit.cli.aperture_args.aperture_from_args`) and passed whole.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import bokehfit.kernels
import bokehfit.scene
from bokehfit.apertures import make_aperture
from bokehfit.errors import InputError
from bokehfit.kernels import compute_kernel, render_kernel
from bokehfit.scene import make_lens

#: Parameter names that would carry a piece of an aperture beside the Aperture.
LOOSE_FEATURES = frozenset(
    {"shape", "angle_deg", "blades", "aspect", "roundness", "squeeze", "vignetting", "rim", "chromatic", "mask"}
)
PACKAGES = (bokehfit.kernels, bokehfit.scene)
#: Public callables whose parameter of one of those names is not the aperture's, with why.
NOT_THE_APERTURES = {
    "bokehfit.scene.Box": "angle_deg is the box's own turn about +y in the scene",
    "bokehfit.scene.geometry.Box": "angle_deg is the box's own turn about +y in the scene",
}


def _modules():
    for package in PACKAGES:
        yield package
        for info in pkgutil.iter_modules(package.__path__, package.__name__ + "."):
            yield importlib.import_module(info.name)


def _public_callables():
    """(qualified name, callable) of every name in a module's ``__all__``, and the public methods of its classes."""
    seen = set()
    for module in _modules():
        for name in getattr(module, "__all__", ()):
            value = getattr(module, name)
            if id(value) in seen or not callable(value):
                continue
            seen.add(id(value))
            yield f"{module.__name__}.{name}", value
            if inspect.isclass(value):
                for attr, member in vars(value).items():
                    if not attr.startswith("_") and inspect.isfunction(member):
                        yield f"{module.__name__}.{name}.{attr}", member


def _parameters(function) -> list[str]:
    try:
        return list(inspect.signature(function).parameters)
    except (TypeError, ValueError):  # builtins and the like
        return []


def test_the_scan_sees_the_public_api():
    names = {name for name, _ in _public_callables()}
    assert {"bokehfit.kernels.compute_kernel", "bokehfit.kernels.render_kernel", "bokehfit.scene.render",
            "bokehfit.scene.make_lens"} <= names


def test_no_public_signature_takes_loose_aperture_features():
    offences = {
        name: sorted(set(_parameters(function)) & LOOSE_FEATURES)
        for name, function in _public_callables()
        if set(_parameters(function)) & LOOSE_FEATURES and name not in NOT_THE_APERTURES
    }
    assert not offences, f"take an Aperture instead of its pieces: {offences}"


@pytest.mark.parametrize("function", [compute_kernel, render_kernel])
def test_kernels_refuse_a_shape_name(function):
    with pytest.raises(InputError, match="aperture must be an Aperture"):
        function("hexagon", 20.0, 32)


def test_make_lens_refuses_a_shape_name():
    with pytest.raises(InputError, match="aperture must be an Aperture"):
        make_lens("hexagon", fstop=2.0, focus_distance_m=0.7)


def test_the_kernel_keeps_the_aperture_it_was_given():
    aperture = make_aperture("ngon", 12.0, blades=7, roundness=0.3, squeeze=1.2)
    kernel = compute_kernel(aperture, 16.0, 24)
    assert kernel.aperture is aperture
    assert make_lens(aperture, fstop=2.0, focus_distance_m=0.7).aperture is aperture
