"""The aperture models the fitter tries: each a shape family's aperture with its free parameters."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from bokehfit.apertures import SHAPES, Aperture, make_aperture

__all__ = ["Family", "FAMILIES", "families_for", "MAX_FIT_BLADES"]

#: Blade counts tried for ``ngon`` beyond the named shapes (3, 4, 5, 6).
MAX_FIT_BLADES = 12
#: Parameters every family has (design.md §8): centre (2), size, plateau, background and edge blur.
DISC_PARAMETERS = 6


@dataclass(frozen=True)
class Family:
    """A shape family: the aperture at angle 0 whose :attr:`Aperture.parameters` the fit varies.

    Parameters counted for model selection (design.md §8): the
    ``DISC_PARAMETERS`` of every disc, the aperture's own parameters (the
    angle for all but the circle, the slit's aspect, each feature switched
    on), and the blade count where the shape leaves it free (a generic ngon).
    """

    aperture: Aperture

    @property
    def name(self) -> str:
        """The shape's label, then each feature the family varies: ``ngon(7)``, ``ngon(7)+roundness``."""
        return "+".join((self.aperture.label, *self.aperture.enabled_features))

    @property
    def base(self) -> Family:
        """The family of the same shape with no feature varied (a rounded 7-gon's is the straight 7-gon's)."""
        if not self.aperture.features:
            return self
        return Family(dataclasses.replace(self.aperture, features=frozenset(), roundness=0.0))

    @property
    def rounded(self) -> Family | None:
        """The same shape with its blades' roundness fitted too (None where the shape has no blades to round)."""
        aperture = self.aperture
        if not aperture.spec.rounds or aperture.has_roundness:
            return None
        return Family(aperture.with_features("roundness"))

    @property
    def parameters(self) -> int:
        return DISC_PARAMETERS + len(self.aperture.parameters) + int(self.aperture.spec.takes_blades)

    def at(self, **values: float) -> Aperture:
        """The family's aperture with those of ``values`` that are its parameters (the others are ignored)."""
        own = {name: float(value) for name, value in values.items() if name in self.aperture.parameters}
        return self.aperture.replace(**own) if own else self.aperture


#: Every registry shape with its blade count fixed (the circle first: the simplest model),
#: then the n-gons of 7 to ``MAX_FIT_BLADES`` blades.
FAMILIES: tuple[Family, ...] = (
    # A mask (design.md §3b) is given, not fitted: discs cannot tell its image.
    *(Family(make_aperture(name)) for name, spec in SHAPES.items() if not spec.takes_blades and not spec.tabulated),
    *(Family(make_aperture(f"ngon({n})")) for n in range(7, MAX_FIT_BLADES + 1)),
)


def families_for(shapes: list[str] | None) -> tuple[Family, ...]:
    """The families to try: all, or those named in ``shapes`` (see :meth:`Aperture.is_named`)."""
    from bokehfit.errors import InputError

    if not shapes:
        return FAMILIES
    selected, unknown = set(), []
    for text in shapes:
        try:  # "ngon(9)" names the 9-gon; ngon(5) the pentagon; a bare "ngon" every n-gon family
            matches = {f for f in FAMILIES if f.aperture.is_named(text)}
        except InputError:
            matches = set()
        selected |= matches
        if not matches:
            unknown.append(text)
    if unknown:
        known = {f.aperture.shape for f in FAMILIES} | {f.name for f in FAMILIES}
        raise InputError(f"--shapes must name shapes among {', '.join(sorted(known))} (got {', '.join(unknown)})")
    return tuple(f for f in FAMILIES if f in selected)
