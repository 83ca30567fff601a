"""A request body's checks and parsing: its size cap, the scan of a JSON body before parsing, the strict parse.

Bodies reach this module only once their declared length is within
``MAX_BODY_BYTES`` (the server checks the Content-Length before a byte of the
body is read: :mod:`bokehfit.view.handler`). JSON bodies are scanned in linear
time for their nesting and number of values before they are parsed
(:func:`json_shape`, :func:`parse_json_body`), and every number is short and
finite, so that no body, whatever its bytes, costs more than linear time and
bounded memory to refuse or to read. A refusal is one line that describes what
was sent briefly (:func:`brief`), never a huge repr.
"""

from __future__ import annotations

import gc
import json
import math
import re
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import orjson

from bokehfit.errors import InputError

__all__ = [
    "MAX_BODY_BYTES",
    "JsonShape",
    "json_depth",
    "json_shape",
    "parse_json_body",
]

#: Largest request body of POST /matched and POST /mask (bytes).
MAX_BODY_BYTES = 8 * 2**20
#: Deepest nesting of arrays and objects in a JSON body (a compare result nests 4 deep).
MAX_JSON_DEPTH = 32
#: Longest integer literal in a JSON body (digits; 2**64 has 20).
MAX_JSON_INT_DIGITS = 32
#: Numbers with an exponent of three digits read one by one for the float range;
#: a body with more is refused (a compare result has none or a few).
MAX_JSON_BIG_EXPONENTS = 1000
#: JSON's white space at the start of a document.
_JSON_SPACE = re.compile(r"[ \t\r\n]*")
#: Most values (and keys) in a JSON body. A compare result (written with indent=1)
#: spends at least 14 bytes a value: at most 600,000 in MAX_BODY_BYTES. A million
#: empty objects take 73 MB once parsed (2.9 MiB of text); MAX_BODY_BYTES of them
#: would take 200 MB.
MAX_JSON_VALUES = 1_000_000


def brief(value, limit: int = 40) -> str:
    """``value`` described in one short line, for an error message (never a huge repr)."""
    if isinstance(value, list):
        return f"an array of {len(value)} items"
    if isinstance(value, dict):
        return f"an object of {len(value)} keys"
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        return f"an integer of {len(str(value)) if value.bit_length() < 10_000 else 'thousands of'} digits"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def finite_number(name: str, value) -> float:
    """``value`` as a float, or ``InputError`` naming ``name`` where it is not a finite JSON number."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            number = float(value)
        except OverflowError:  # an int beyond the float range
            number = math.inf
        if math.isfinite(number):
            return number
    raise InputError(f"{name} must be a finite number (got {brief(value)})")


#: Bytes the JSON scanner looks at in one step (its temporaries are a few times this).
_SCAN_CHUNK = 1 << 18
#: The classes of each byte value, one bit a class, so that one table lookup sorts a step's bytes.
_OPEN, _CLOSE, _SEPARATOR, _NUMBER, _QUOTE, _BACKSLASH, _DIGIT, _SIGN, _EXPONENT = (1 << i for i in range(9))
_BYTE_CLASS = np.zeros(256, dtype=np.uint16)
for _chars, _class in (
    (b"[{", _OPEN), (b"]}", _CLOSE), (b",:", _SEPARATOR), (b'"', _QUOTE), (b"\\", _BACKSLASH),
    (b".", _NUMBER), (b"0123456789", _NUMBER | _DIGIT), (b"+-", _NUMBER | _SIGN), (b"eE", _NUMBER | _EXPONENT),
):
    _BYTE_CLASS[list(_chars)] = _class


@dataclass(frozen=True)
class JsonShape:
    """What :func:`json_shape` counts in a JSON text, without parsing it."""

    depth: int  #: deepest nesting of arrays and objects
    values: int  #: an upper bound of the values and keys: separators and openings outside strings, plus one
    longest_number: int  #: characters of the longest run of number characters (0-9 + - . e E) outside strings
    longest_number_end: int  #: index just past that run
    #: Where an exponent of three digits or more starts outside strings (the only way a short
    #: number leaves the float range), the first MAX_JSON_BIG_EXPONENTS + 1 of them.
    big_exponents: tuple[int, ...]


def _run_ends(mask: np.ndarray, index: np.ndarray, carried: int) -> np.ndarray:
    """For each byte, the index of the last byte at or before it outside ``mask``; before the step, -1 - ``carried``.

    ``i - result[i]`` is then the length of the run of ``mask`` bytes ending at ``i``
    (counting the ``carried`` ones of the step before).
    """
    return np.maximum.accumulate(np.where(mask, np.int32(-1 - carried), index))


def json_shape(body: bytes | bytearray) -> JsonShape:
    """Nesting depth, number of values, longest number and large exponents of the JSON text ``body``, strings left out.

    One pass in fixed steps, linear in the length whatever the bytes: a quote
    is the end of a string unless an odd run of backslashes precedes it (the
    JSON escapes; outside strings a backslash is an error that parsing
    reports), so strings are found without a regular expression that could
    backtrack, and nothing is recursed into.
    """
    data = np.frombuffer(body, dtype=np.uint8)
    backslashes = 0  # the run of backslashes that ends the step before (its parity is what counts)
    number = 0  # the run of number characters that ends the step before
    inside = 0  # this step starts inside a string
    depth = deepest = values = longest = longest_end = 0
    big_exponents: list[int] = []
    for start in range(0, len(data), _SCAN_CHUNK):
        # The step and the 4 bytes after it: an exponent's digits may lie beyond the step.
        ahead = _BYTE_CLASS[data[start : start + _SCAN_CHUNK + 4]]
        kind = ahead[:_SCAN_CHUNK].copy()
        ahead = np.concatenate((ahead[1:], np.zeros(5 - (len(ahead) - len(kind)), dtype=ahead.dtype)))
        index = np.arange(len(kind), dtype=np.int32)
        last_other = _run_ends((kind & _BACKSLASH).astype(bool), index, backslashes & 1)
        run_before = index - 1 - np.concatenate(([np.int32(-1 - (backslashes & 1))], last_other[:-1]))
        quote = (kind & _QUOTE).astype(bool) & ((run_before & 1) == 0)
        in_string = ((np.cumsum(quote, dtype=np.int32) + inside) & 1).astype(bool)
        kind[in_string | quote] = 0  # what is left is outside strings
        opens = (kind & _OPEN).astype(bool)
        steps = opens.astype(np.int8) - (kind & _CLOSE).astype(bool)
        level = depth + np.cumsum(steps, dtype=np.int32)
        deepest = max(deepest, int(level.max()))
        depth = int(level[-1])
        values += int(np.count_nonzero(kind & (_OPEN | _SEPARATOR)))
        runs = index - _run_ends((kind & _NUMBER).astype(bool), index, number)
        end = int(np.argmax(runs))
        if runs[end] > longest:
            longest, longest_end = int(runs[end]), start + end + 1
        if len(big_exponents) <= MAX_JSON_BIG_EXPONENTS:
            # ahead[i + k] is the class of byte i + 1 + k: e or E, then a sign or not, then three digits.
            n = len(kind)
            digits = [(ahead[k : k + n] & _DIGIT).astype(bool) for k in range(4)]
            three = (digits[0] & digits[1] & digits[2]) | ((ahead[:n] & _SIGN).astype(bool) & digits[1] & digits[2] & digits[3])
            found = np.flatnonzero((kind & _EXPONENT).astype(bool) & three)
            big_exponents += (found[: MAX_JSON_BIG_EXPONENTS + 1 - len(big_exponents)] + start).tolist()
        inside = int(in_string[-1])
        backslashes = int(len(kind) - 1 - last_other[-1])
        number = int(runs[-1])
    return JsonShape(deepest, values + 1, longest, longest_end, tuple(big_exponents))


def json_depth(body: bytes | bytearray) -> int:
    """Deepest nesting of arrays and objects in the JSON text ``body`` (:func:`json_shape`)."""
    return json_shape(body).depth


@contextmanager
def collector_paused():
    """The cyclic garbage collector off inside (unless it was off already).

    Parsed JSON holds no cycles: the collector's passes over a million new
    lists, during the parse and again while they are alive, are pure cost.
    Inside, objects are still freed as soon as the last reference goes.
    """
    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collecting:
            gc.enable()


def _check_exponents(body: bytes | bytearray, positions: tuple[int, ...]) -> None:
    """Refuse a number whose exponent (at ``positions``, of three digits or more) leaves the float range (1e999).

    Each such number is read with ``float``; more than ``MAX_JSON_BIG_EXPONENTS``
    of them are refused unread. The numbers are short already (:func:`parse_json_body`).
    """
    if len(positions) > MAX_JSON_BIG_EXPONENTS:
        raise InputError(f"the body is not JSON: more than {MAX_JSON_BIG_EXPONENTS} numbers with exponents of three digits")
    for position in positions:
        start = end = position
        while start > 0 and _BYTE_CLASS[body[start - 1]] & _NUMBER:
            start -= 1
        while end < len(body) and _BYTE_CLASS[body[end]] & _NUMBER:
            end += 1
        token = bytes(body[start:end])
        try:
            finite = math.isfinite(float(token))
        except ValueError:
            continue  # not a number: parsing reports it
        if not finite:
            raise InputError(f"the body is not JSON: the number {token.decode('ascii')} is beyond the float range")


def parse_json_body(
    body: bytes | bytearray, *, max_depth: int = MAX_JSON_DEPTH, max_int_digits: int = MAX_JSON_INT_DIGITS, max_values: int = MAX_JSON_VALUES,
    object_only: bool = False,
):
    """A request body parsed as strict JSON, with bounded nesting, size and numbers, in time linear in its length.

    Parameters
    ----------
    body : bytes
        UTF-8 JSON text.
    max_depth : int
        Deepest nesting of arrays and objects accepted (see :func:`json_shape`).
    max_int_digits : int
        Longest integer literal accepted (digits).
    max_values : int
        Most values and keys accepted (:func:`json_shape`): what bounds the
        parse's time and memory, whatever the body's length.
    object_only : bool
        Refuse, before parsing, a document that is not a JSON object (a
        compare result is one): its values then cost no parse.

    Returns
    -------
    object
        The parsed value; every number in it is a finite float or a bounded int.

    Raises
    ------
    InputError
        One line where the body is not UTF-8, not JSON, nested too deep,
        holds too many values, or holds NaN, ±Infinity, a float beyond the
        float range (1e999) or a longer integer.

    Notes
    -----
    Every check runs on the bytes, before parsing, in time linear in the
    length: :func:`json_shape` gives the depth, the number of values and the
    longest number, which may have at most ``max_int_digits`` digits and a
    sign (a float's shortest repr has at most 24 characters); then the few
    numbers with an exponent of three digits, the only short ones that can
    leave the float range, are read one by one (at most
    ``MAX_JSON_BIG_EXPONENTS``). The body is then parsed by the standard
    orjson (the standard library's C parser where orjson refuses it, for its
    messages), numbers included (a Python hook per number would
    cost more than 0.1 s per MiB of short numbers), with the cyclic garbage
    collector paused (it would walk every new list again and again, for
    nothing: parsed JSON holds no cycles).
    """

    def no_constant(name: str):
        raise ValueError(f"{name} is not a JSON number")

    shape = json_shape(body)  # before decoding: a refused body costs no more memory
    if shape.depth > max_depth:
        raise InputError(f"the body nests {shape.depth} deep: at most {max_depth} is read")
    if shape.values > max_values:
        raise InputError(f"the body holds about {shape.values} values: at most {max_values} are read")
    if shape.longest_number > max_int_digits + 1:
        token = bytes(body[shape.longest_number_end - shape.longest_number : shape.longest_number_end])
        if re.fullmatch(rb"-?[0-9]+", token):
            raise InputError(f"the body is not JSON: an integer of {len(token.lstrip(b'-'))} digits (at most {max_int_digits})")
        raise InputError(f"the body is not JSON: a number of {len(token)} characters (at most {max_int_digits + 1})")
    _check_exponents(body, shape.big_exponents)
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError(f"the body is not JSON: it is not UTF-8 (byte {error.start})") from None
    start = _JSON_SPACE.match(text).end()
    if object_only and text[start : start + 1] != "{":
        raise InputError("the body must be a `bokehfit compare --json` result: a JSON object with an 'aperture' object")
    with collector_paused():
        try:
            # orjson (strict RFC 8259: no NaN or Infinity) parses short numbers about four times
            # faster than the standard library; its refusals are read again by the standard
            # library's parser, whose messages name what is wrong in this module's words.
            return orjson.loads(text)
        except orjson.JSONDecodeError:
            pass
        try:
            return json.loads(text, parse_constant=no_constant)
        except RecursionError:  # not reached after the depth check; kept as the last guard
            raise InputError(f"the body nests deeper than {max_depth}: at most {max_depth} is read") from None
        except ValueError as error:  # JSONDecodeError and the hook's refusal
            raise InputError(f"the body is not JSON: {error}") from None

