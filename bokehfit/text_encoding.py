"""Text that any file can hold: a file name that is not valid UTF-8 becomes U+FFFD instead of failing.

A file name that is not valid UTF-8 reaches Python as lone surrogates (PEP 383). Text
written into a page or a report goes through :func:`encode_text`; text stored elsewhere
(a survey's database) through :func:`replace_surrogates`.
"""

from __future__ import annotations

import re

__all__ = ["encode_text", "replace_surrogates"]


def encode_text(text: str) -> bytes:
    """``text`` as UTF-8, where characters UTF-8 can't hold become U+FFFD.

    A file name that is not valid UTF-8 reaches Python as lone surrogates (PEP 383);
    written into a page or a report they would make the whole text unencodable.
    """
    try:
        return text.encode("utf-8")
    except UnicodeEncodeError:
        return replace_surrogates(text).encode("utf-8")


def replace_surrogates(text: str) -> str:
    """``text`` with every lone surrogate (an undecodable byte of a file name, PEP 383) made U+FFFD."""
    return _SURROGATE.sub("\ufffd", text)


_SURROGATE = re.compile("[\ud800-\udfff]")
