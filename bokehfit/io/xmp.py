"""XMP: the simple properties of a packet (lens, focus distance, ICC profile name, ...).

The XMP packet is untrusted text: it is read by :func:`parse_xmp` with the
expat XML parser (linear time, no regular expressions), only up to
:data:`XMP_MAX_BYTES`, and a packet that declares a document type (the only
way to define entities) is ignored.
"""

from __future__ import annotations

from typing import Mapping
from xml.parsers import expat

__all__ = ["XMP_MAX_BYTES", "parse_xmp", "xmp_property"]

#: Largest XMP packet read (bytes). Camera and editor packets are a few kB; a JPEG APP1
#: segment holds at most 64 kB. Larger packets are ignored, not parsed.
XMP_MAX_BYTES = 1 << 20


class _DocumentTypeRefused(Exception):
    """An XMP packet declared a document type (entities): it is not read."""


def parse_xmp(xmp: bytes | str | None) -> dict[str, str]:
    """The simple properties of an XMP packet: ``{"prefix:Name": value}``, first occurrence of each.

    A property is an attribute (``aux:Lens="..."``, typically on ``rdf:Description``) or an
    element that holds only text (``<aux:Lens>...</aux:Lens>``); names are kept as written,
    prefix included. The packet is read with expat, which takes time linear in its size.
    Packets over :data:`XMP_MAX_BYTES` or with a ``<!DOCTYPE`` give ``{}``; a packet that is
    not well-formed gives what was read before the error.

    Examples
    --------
    >>> parse_xmp(b'<x:xmpmeta><rdf:Description aux:Lens="EF85mm f/1.8 USM"/></x:xmpmeta>')
    {'aux:Lens': 'EF85mm f/1.8 USM'}
    """
    if not xmp:
        return {}
    data = xmp.encode("utf-8", "replace") if isinstance(xmp, str) else bytes(xmp)
    if len(data) > XMP_MAX_BYTES:
        return {}
    properties: dict[str, str] = {}
    open_elements: list[list] = []  # [name, text pieces, has child elements]

    def start(name: str, attributes: dict) -> None:
        if open_elements:
            open_elements[-1][2] = True
        for key, value in attributes.items():
            if not key.startswith("xmlns"):
                properties.setdefault(key, value)
        open_elements.append([name, [], False])

    def end(name: str) -> None:
        _, pieces, has_children = open_elements.pop()
        if not has_children:
            properties.setdefault(name, "".join(pieces))

    def text(piece: str) -> None:
        if open_elements:
            open_elements[-1][1].append(piece)

    def document_type(*_args) -> None:
        raise _DocumentTypeRefused

    parser = expat.ParserCreate()  # no namespace processing: names keep the prefixes as written
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.CharacterDataHandler = text
    parser.StartDoctypeDeclHandler = document_type
    try:
        parser.Parse(data.rstrip(b"\x00"), True)
    except _DocumentTypeRefused:
        return {}
    except expat.ExpatError:
        pass  # keep what was read before the damage
    return {name: value.strip() for name, value in properties.items() if value.strip()}


def xmp_property(xmp: bytes | str | Mapping[str, str] | None, name: str) -> str | None:
    """The value of an XMP property ``prefix:Name`` (element or attribute form), or None.

    ``xmp`` is the packet, or what :func:`parse_xmp` made of it (to read several properties).

    Examples
    --------
    >>> xmp_property(b"<aux:ApproximateFocusDistance>727/100</aux:ApproximateFocusDistance>",
    ...              "aux:ApproximateFocusDistance")
    '727/100'
    """
    properties = xmp if isinstance(xmp, Mapping) else parse_xmp(xmp)
    return properties.get(name)
