"""The seed's scene: a Cornell box with a mirror rear wall, mirror balls and a fine floor grid.

Dimensions follow the original Cornell box (Goral et al. 1984; the measured
data at https://www.graphics.cornell.edu/online/box/data.html), squared off to
a 0.555 m cube: red wall on the left (x = 0.555), green on the right (x = 0),
white floor and ceiling, the 130 × 105 mm ceiling light, the short block
(0.165 m, turned by 16.6° as in the data). The tall block is left out; the
rear wall is a mirror; four mirror balls stand at depths from 0.62 m to 1.02 m.
The room is closed behind the camera by a white wall (seen in the mirror), so
that no camera ray leaves the scene.

The floor is white with a checker of 4 cm squares (the odd ones at 55 %) and
dark 1 mm lines every 1 cm: fine enough that its sharp band shows where the
focus plane cuts it. The camera (35 mm lens on a 36 mm sensor, 54.4° across)
stands on the box's axis at mid-height, 0.55 m in front of the opening, and
looks at the mirror.

Colours are the usual RGB approximations of the measured reflectances (as in
Mitsuba's and pbrt's Cornell boxes); the light's radiance is twice that of
Mitsuba 3's ``cbox`` scene (its colour, and an exposure that suits this box,
whose dark mirror takes the place of a lit white wall).
"""

from __future__ import annotations

import math

from bokehfit.scene.geometry import Box, Material, Pose, Quad, Scene, Sphere

__all__ = ["cornell_box", "ROOM_SIZE_M", "FRONT_WALL_Z_M", "CAMERA_Z_M"]

#: Side of the box (x: width, y: height; the box's own depth from the opening z = 0 to the mirror).
ROOM_SIZE_M = 0.555
#: The closing wall behind the camera, and the camera, on the z axis.
FRONT_WALL_Z_M = -0.6
CAMERA_Z_M = -0.55
#: The ceiling light hangs this far below the ceiling (so that its back faces the ceiling).
LIGHT_DROP_M = 0.0005
#: Default focus: the front of the ball on the short block.
DEFAULT_FOCUS_M = 0.7

_WHITE = (0.725, 0.71, 0.68)
_MATERIALS = (
    Material("white", "diffuse", albedo=_WHITE),
    Material("red", "diffuse", albedo=(0.63, 0.065, 0.05)),
    Material("green", "diffuse", albedo=(0.14, 0.45, 0.091)),
    Material(
        "floor",
        "diffuse",
        albedo=_WHITE,
        checker_size=0.04,
        checker_contrast=0.55,
        line_spacing=0.01,
        line_width=0.001,
        line_albedo=0.03,
    ),
    Material("mirror", "mirror", albedo=(0.9, 0.9, 0.9)),
    Material("light", "emitter", emission=(2 * 18.387, 2 * 13.9873, 2 * 6.75357)),
)


def cornell_box() -> Scene:
    """The Cornell box described in the module notes."""
    s = ROOM_SIZE_M
    z0 = FRONT_WALL_Z_M
    depth = s - z0
    y_light = s - LIGHT_DROP_M
    quads = (
        # Ceiling light (original: x 213-343 mm, z 227-332 mm), emitting downwards.
        Quad((0.213, y_light, 0.227), (0.130, 0.0, 0.0), (0.0, 0.0, 0.105), "light"),
        # Floor: texture coordinates (z − z0, x), metres; normal +y.
        Quad((0.0, 0.0, z0), (0.0, 0.0, depth), (s, 0.0, 0.0), "floor"),
        Quad((0.0, s, z0), (s, 0.0, 0.0), (0.0, 0.0, depth), "white"),  # ceiling, normal −y
        Quad((0.0, 0.0, s), (0.0, s, 0.0), (s, 0.0, 0.0), "mirror"),  # rear wall, normal −z
        Quad((0.0, 0.0, z0), (s, 0.0, 0.0), (0.0, s, 0.0), "white"),  # wall behind the camera, +z
        Quad((s, 0.0, z0), (0.0, 0.0, depth), (0.0, s, 0.0), "red"),  # left wall, normal −x
        Quad((0.0, 0.0, z0), (0.0, s, 0.0), (0.0, 0.0, depth), "green"),  # right wall, normal +x
    )
    # Short block: top corners (130, 65), (82, 225), (240, 272), (290, 114) mm in (x, z);
    # centre (185.5, 169), sides 165 mm, one side along (158, 47): 16.6°.
    block_half = 0.0825
    block = Box((0.1855, block_half, 0.169), (block_half, block_half, block_half), math.degrees(math.atan2(47.0, 158.0)), "white")
    spheres = (
        Sphere((0.43, 0.04, 0.07), 0.04, "mirror"),  # front left, on the floor
        Sphere((0.1855, 2 * block_half + 0.035, 0.169), 0.035, "mirror"),  # on the short block
        Sphere((0.37, 0.055, 0.36), 0.055, "mirror"),  # where the tall block stood
        Sphere((0.12, 0.03, 0.47), 0.03, "mirror"),  # back right, near the mirror
    )
    return Scene(
        name="cornell",
        materials=_MATERIALS,
        quads=quads,
        boxes=(block,),
        spheres=spheres,
        pose=Pose((s / 2.0, s / 2.0, CAMERA_Z_M)),
        default_focus_m=DEFAULT_FOCUS_M,
    )
