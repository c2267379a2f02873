"""One parser for the integers posecrb reads as text, and a safe way to show any value in a message.

Integers come as text from three places: option values (``--anchor``, ``--every``, ``--seed``,
...), the ids of g2o and TORO files, and the library's text arguments (``poses="3,7,10-12"``).
Python's ``int(text)`` takes more than posecrb wants (``1_0``, non-ASCII digits, Unicode spaces)
and refuses more than ``sys.get_int_max_str_digits()`` digits (4300 by default) with a
``ValueError``; ``str()`` and ``repr()`` of such an int raise the same error. So:

* ``parse_int`` takes plain ASCII decimal digits with an optional sign and rejects anything with
  more digits than the bound of its range (after the sign and leading zeros) before ``int()``
  ever sees it: the conversion is then at most 19 digits for an int64 range;
* ``check_int`` checks an integer the library was given (huge Python ints compare fine);
* ``shown`` is ``repr`` for messages, except that an integer of more than ``SHOWN_DIGITS`` digits
  is shown by its size and a long text by its beginning (a message never raises).

Both checks raise ``IntegerError`` with the reason as a predicate (``"is not in 1..1000"``); each
caller turns it into its own error: a usage error (exit 2) for an option, a ``ParseError`` with
the file and line for a file, an ``ArgumentError`` for the library.
"""
from __future__ import annotations

import math
import numbers
import re
from typing import Any

INT64_MIN = -(2 ** 63)
INT64_MAX = 2 ** 63 - 1
# An integer of more digits than this is shown by its size in messages.
SHOWN_DIGITS = 40
# A text longer than this is shown by its first SHOWN_TEXT characters and "...".
SHOWN_TEXT = 60

_PLAIN_INT = re.compile(r"([+-]?)([0-9]+)")


class IntegerError(ValueError):
    """An integer (or its text) that is malformed or out of range; ``str(exc)`` is the reason as a
    predicate, to follow the value in the caller's message."""


def _range(lo: int, hi: int) -> str:
    return f"is not in {lo}..{hi}"


def parse_int(text: str, *, lo: int = INT64_MIN, hi: int = INT64_MAX, what: str = "an integer") -> int:
    """The integer written in ``text``: plain ASCII decimal digits with an optional sign (blanks
    around it are ignored), within ``[lo, hi]``.

    Parameters
    ----------
    text : str
        The text of one integer.
    lo, hi : int
        The range (default int64's).
    what : str
        What the integer is, for the message (``"a pose id"``).

    Returns
    -------
    int

    Raises
    ------
    IntegerError
        ``text`` is not plain digits, or the integer is outside ``[lo, hi]``; a text with more
        digits than ``lo`` and ``hi`` have is refused before any conversion.

    Examples
    --------
    >>> parse_int(" 0042 ", lo=0, hi=100)
    42
    >>> parse_int("1" * 5000, lo=0, hi=100)
    Traceback (most recent call last):
    ...
    posecrb.core.integers.IntegerError: is not in 0..100
    >>> parse_int("1_0")
    Traceback (most recent call last):
    ...
    posecrb.core.integers.IntegerError: is not an integer (plain decimal digits)
    """
    match = _PLAIN_INT.fullmatch(text.strip()) if isinstance(text, str) else None
    if match is None:
        raise IntegerError(f"is not {what} (plain decimal digits)")
    sign, digits = match.groups()
    digits = digits.lstrip("0") or "0"
    if len(digits) > max(len(str(abs(lo))), len(str(abs(hi)))):
        raise IntegerError(_range(lo, hi))
    return check_int(int(sign + digits), lo=lo, hi=hi, what=what)


def check_int(value: Any, *, lo: int = INT64_MIN, hi: int = INT64_MAX, what: str = "an integer") -> int:
    """``value`` as an ``int`` when it is an integer (``numbers.Integral``: not a bool, not a float
    such as 1.0) within ``[lo, hi]``; else ``IntegerError``.

    Examples
    --------
    >>> check_int(10 ** 5000, lo=1, hi=10)
    Traceback (most recent call last):
    ...
    posecrb.core.integers.IntegerError: is not in 1..10
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):     # (numpy.bool_ is no Integral)
        raise IntegerError(f"is not {what}")
    number = int(value)               # (of an integer, not of a text: no digit limit)
    if not lo <= number <= hi:
        raise IntegerError(_range(lo, hi))
    return number


def shown(value: Any) -> str:
    """``repr(value)`` for a message, short and safe: an integer of more than ``SHOWN_DIGITS``
    digits as ``<an integer of about N digits>`` (``repr`` of one over 4300 digits raises), a
    text of more than ``SHOWN_TEXT`` characters cut, anything whose ``repr`` fails by its type.

    Examples
    --------
    >>> shown(10 ** 5000)
    '<an integer of about 5001 digits>'
    >>> shown([1, 2])
    '[1, 2]'
    """
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        bits = int(value).bit_length()
        if bits > SHOWN_DIGITS * math.log2(10):
            return f"<an integer of about {int(bits * math.log10(2)) + 1} digits>"
    if isinstance(value, (str, bytes)) and len(value) > SHOWN_TEXT:
        return repr(value[:SHOWN_TEXT]) + "..."
    try:
        return repr(value)
    except ValueError:
        return f"<a {type(value).__name__} too large to show>"


def shown_text(value: Any) -> str:
    """``str(value)`` for a message, as ``shown`` is ``repr``: the same safe forms for huge
    integers, long texts and values whose ``str`` fails; sequences item by item, space-separated
    (the command line's spelling of a multiple option)."""
    if isinstance(value, (list, tuple)):
        return " ".join(shown_text(v) for v in value)
    if isinstance(value, str):
        return value if len(value) <= SHOWN_TEXT else value[:SHOWN_TEXT] + "..."
    text = shown(value)
    return text if text.startswith("<") else str(value)
