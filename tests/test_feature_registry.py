"""The §3b features' registry (``bokehfit.apertures.features``): one record per feature the model knows,
and each record agrees with the :class:`~bokehfit.apertures.Aperture` it describes.

The fit and the report loop over these records instead of comparing feature names
(``tests/test_one_model.py`` checks that), so a record that disagreed with the model would
start, bound or report a feature wrongly: each field is checked against the model here.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect

import numpy as np
import pytest

from bokehfit.apertures import FEATURE_SPECS, FEATURES, SHAPES, FeatureEvidence, FeatureSpec, make_aperture
from bokehfit.apertures import features as registry
from bokehfit.validate import RANGES

#: A shape each feature applies to: the circle, or the hexagon where the feature needs blades.
SHAPE_FOR = {name: "circle" if spec.applies(SHAPES["circle"]) else "hexagon" for name, spec in FEATURE_SPECS.items()}
#: The evidence a fit may give: a disc near the centre or at a corner, the discs stretched alike or not.
EVIDENCE = (
    FeatureEvidence(farthest_field=0.3, shared_squeeze=None),
    FeatureEvidence(farthest_field=0.7, shared_squeeze=1.3),
    FeatureEvidence(farthest_field=1.0, shared_squeeze=0.8),
)


def _base(name: str):
    return make_aperture(SHAPE_FOR[name], 10.0)


def test_every_feature_has_one_record_in_the_models_order():
    assert tuple(FEATURE_SPECS) == FEATURES == ("roundness", "squeeze", "rim", "vignetting", "chromatic")
    assert all(spec.name == name for name, spec in FEATURE_SPECS.items())
    assert sorted(registry.JSON_ORDER) == sorted(FEATURES)


@pytest.mark.parametrize("name", FEATURES)
def test_a_records_parameters_are_the_apertures_when_the_feature_is_on(name):
    spec, base = FEATURE_SPECS[name], _base(name)
    on = base.with_features(name)
    added = [p for p in on.parameters if p not in base.parameters]
    assert added == list(spec.parameters)
    assert spec.is_on(on) and not spec.is_on(base)
    assert name in on.enabled_features and name not in base.enabled_features
    for parameter, quantity in zip(spec.parameters, spec.quantities):
        assert on.parameters[parameter].bounds == (RANGES[quantity].low, RANGES[quantity].high)


@pytest.mark.parametrize("name", FEATURES)
def test_neutral_values_give_the_kernel_of_the_feature_off(name):
    from bokehfit.kernels import render_kernel

    base = _base(name)
    on = base.with_features(name)
    assert getattr(base, name) == FEATURE_SPECS[name].neutral
    off = render_kernel(base, 15.0, 21, method="exact", field_position=(0.5, 0.3))
    kernel = render_kernel(on, 15.0, 21, method="exact", field_position=(0.5, 0.3))
    channels = kernel if kernel.ndim == 3 else kernel[..., None]  # colour on: one kernel a channel
    for channel in np.moveaxis(channels, -1, 0):  # a barrel that cuts nothing still goes through the clipping: ~1e-17
        np.testing.assert_allclose(channel, off, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("evidence", EVIDENCE, ids=["central", "stretched", "corner"])
@pytest.mark.parametrize("name", FEATURES)
def test_start_values_lie_inside_the_bounds(name, evidence):
    spec, base = FEATURE_SPECS[name], _base(name)
    start = spec.start(base, evidence)
    assert spec.is_on(start)
    parameters, values = start.parameters, start.values
    for parameter in spec.parameters:
        low, high = parameters[parameter].bounds
        assert low <= values[parameter] <= high, (parameter, values[parameter])


def test_starts_from_the_evidence():
    circle = make_aperture("circle")
    squeezed = FEATURE_SPECS["squeeze"].start(circle, FeatureEvidence(shared_squeeze=1.3))
    assert squeezed.squeeze == 1.3 and FEATURE_SPECS["squeeze"].start(circle, FeatureEvidence()).squeeze == 1.0
    assert FEATURE_SPECS["rim"].start(circle, FeatureEvidence()).rim == registry.RIM_START
    barrel = FEATURE_SPECS["vignetting"].start(circle, FeatureEvidence(farthest_field=0.6)).vignetting
    assert barrel.shift == registry.VIGNETTING_START_SHIFT
    assert barrel.radius == pytest.approx(0.6 * abs(registry.VIGNETTING_START_SHIFT) + registry.VIGNETTING_START_CUT)


def test_a_rim_too_faint_to_show_is_not_shown():
    rim = FEATURE_SPECS["rim"]
    assert rim.shows(make_aperture("circle", rim=registry.MIN_RIM)) and rim.shows(make_aperture("circle", rim=-0.3))
    assert not rim.shows(make_aperture("circle", rim=0.5 * registry.MIN_RIM))
    assert FEATURE_SPECS["squeeze"].shows(make_aperture("circle", squeeze=1.001))  # no least value: always shows


@pytest.mark.parametrize(
    "name, aperture, tested, reported",
    [
        ("roundness", make_aperture("hexagon"), (), True),  # straight blades: roundness 0
        ("roundness", make_aperture("circle"), (), False),  # no blades to round
        ("rim", make_aperture("circle"), ("rim",), True),  # tested, not needed: rim 0
        ("rim", make_aperture("circle"), (), False),
        ("squeeze", make_aperture("circle", squeeze=1.2), (), True),
        ("vignetting", make_aperture("circle"), ("vignetting",), False),  # tested, not kept: null
        ("vignetting", make_aperture("circle", vignetting={"radius": 2.0, "shift": -1.0}), (), True),
        ("chromatic", make_aperture("circle").with_features("chromatic"), (), True),
    ],
)
def test_where_a_feature_is_reported(name, aperture, tested, reported):
    assert FEATURE_SPECS[name].is_reported(aperture, tested) == reported


def test_json_values_and_uncertainties():
    aperture = make_aperture("hexagon", roundness=0.3, vignetting={"radius": 2.0, "shift": -0.5},
                             chromatic={"red": 0.02, "blue": -0.01})
    sigma = {"roundness": 0.01, "vignetting_radius": 0.1, "chromatic_blue": 0.003}
    assert FEATURE_SPECS["roundness"].value(aperture) == 0.3
    assert FEATURE_SPECS["roundness"].uncertainty(sigma) == 0.01
    assert FEATURE_SPECS["vignetting"].value(aperture) == {"radius": 2.0, "shift": -0.5}
    assert FEATURE_SPECS["vignetting"].uncertainty(sigma) == {"radius": 0.1, "shift": None}
    assert FEATURE_SPECS["chromatic"].value(aperture) == {"red": 0.02, "blue": -0.01}
    assert FEATURE_SPECS["chromatic"].uncertainty(sigma) == {"red": None, "blue": 0.003}


def test_a_pairs_members_are_its_value_types_fields():
    aperture = make_aperture("circle").with_features(*FEATURES[1:])
    for spec in FEATURE_SPECS.values():
        if spec.members:
            value = getattr(aperture, spec.name)
            assert tuple(f.name for f in dataclasses.fields(value)) == spec.members


def test_applies_names_the_shapes_that_take_the_feature():
    for shape, spec in SHAPES.items():
        assert FEATURE_SPECS["roundness"].applies(spec) == spec.rounds, shape
        assert all(FEATURE_SPECS[name].applies(spec) for name in FEATURES[1:])


def test_a_bad_record_is_refused():
    with pytest.raises(ValueError, match="reported must be one of shape, tested, set"):
        FeatureSpec("glow", 0.0, ("rim",), reported="always")
    with pytest.raises(ValueError, match="quantities of glow must name a range for each of glow_a, glow_b"):
        FeatureSpec("glow", None, ("rim",), members=("a", "b"))


def test_the_registry_imports_no_bokehfit_module_at_run_time():
    """The records act on an aperture through its methods: the module sits below ``shapes`` without a cycle."""
    tree = ast.parse(inspect.getsource(registry))
    imported = [node.module for node in tree.body if isinstance(node, ast.ImportFrom)]
    assert not [name for name in imported if name and name.startswith("bokehfit")]
