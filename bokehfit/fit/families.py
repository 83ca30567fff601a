"""The aperture models the fitter tries: each shape family with its free parameters."""

from __future__ import annotations

from dataclasses import dataclass

from bokehfit.apertures import Aperture, make_aperture

__all__ = ["Family", "FAMILIES", "families_for", "MAX_FIT_BLADES"]

#: Blade counts tried for ``ngon`` beyond the named shapes (3, 4, 5, 6).
MAX_FIT_BLADES = 12


@dataclass(frozen=True)
class Family:
    """A shape family: the registry shape, its blade count, and how many parameters it adds.

    Parameters counted for model selection (design.md §8): centre (2), size,
    plateau, background and edge blur for every family; the angle for all but
    the circle; the aspect for the slit; the blade count for a generic ngon.
    """

    shape: str
    blades: int | None = None

    @property
    def name(self) -> str:
        return f"ngon({self.blades})" if self.shape == "ngon" else self.shape

    @property
    def parameters(self) -> int:
        count = 6
        if self.shape != "circle":
            count += 1
        if self.shape == "slit":
            count += 1
        if self.shape == "ngon":
            count += 1
        return count

    def aperture(self, angle_deg: float = 0.0, aspect: float | None = None) -> Aperture:
        return make_aperture(
            self.shape,
            angle_deg,
            blades=self.blades if self.shape == "ngon" else None,
            aspect=aspect if self.shape == "slit" else None,
        )


FAMILIES: tuple[Family, ...] = (
    Family("circle"),
    Family("square"),
    Family("slit"),
    Family("triangle"),
    Family("pentagon"),
    Family("hexagon"),
    Family("star"),
    *(Family("ngon", n) for n in range(7, MAX_FIT_BLADES + 1)),
)


def families_for(shapes: list[str] | None) -> tuple[Family, ...]:
    """The families to try: all, or those whose shape (or ``ngon(N)`` name) is listed."""
    if not shapes:
        return FAMILIES
    chosen = tuple(f for f in FAMILIES if f.shape in shapes or f.name in shapes)
    known = {f.shape for f in FAMILIES} | {f.name for f in FAMILIES}
    unknown = [s for s in shapes if s not in known]
    if unknown:
        from bokehfit.errors import InputError

        raise InputError(f"--shapes must name shapes among {', '.join(sorted(known))} (got {', '.join(unknown)})")
    return chosen
