"""Human units for the command line: bandwidths, durations and sizes.

The replay command takes ``--bandwidth 56kbit --rtt 200ms --cache 64MB``; these
functions turn such strings into plain numbers in base units (bits per second,
seconds, bytes) and back into short labels for tables and plots.

Decimal prefixes are SI (``k`` = 1000, ``M`` = 10**6, ``G`` = 10**9, in either case:
a milli-bit makes no sense); binary prefixes (``Ki``, ``Mi``, ``Gi``) are powers of
1024.  For rates and sizes ``B`` (upper case) is a byte and ``b``/``bit`` a bit, so
``56kbps`` is 56,000 bit/s and ``7kB/s`` is 56,000 bit/s too.
"""

from __future__ import annotations

import math
import re

from walkstream.shared.errors import InputError

__all__ = [
    "format_bandwidth",
    "format_bytes",
    "format_duration",
    "parse_bandwidth",
    "parse_duration",
    "parse_size",
]

# A signed decimal number; the sign is matched so that "-5kbit" is reported as
# negative instead of as garbage.  "inf" and "nan" are not numbers here.
_NUMBER = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_QUANTITY = re.compile(rf"^\s*({_NUMBER})\s*([A-Za-zµ/]*)\s*$")

_PREFIXES: dict[str, float] = {
    "": 1.0,
    "k": 1e3,
    "K": 1e3,
    "m": 1e6,
    "M": 1e6,
    "g": 1e9,
    "G": 1e9,
    "ki": 1024.0,
    "Ki": 1024.0,
    "KI": 1024.0,
    "mi": 1024.0**2,
    "Mi": 1024.0**2,
    "MI": 1024.0**2,
    "gi": 1024.0**3,
    "Gi": 1024.0**3,
    "GI": 1024.0**3,
}

# Longest first so that "bits" is not read as prefix "bit" + base "s".
_BIT_BASES = ("bits", "bit", "b")
_BYTE_BASES = ("bytes", "byte", "B")
_RATE_SUFFIXES = ("/sec", "/s", "ps")

_DURATIONS: dict[str, float] = {
    "": 1.0,
    "s": 1.0,
    "sec": 1.0,
    "secs": 1.0,
    "second": 1.0,
    "seconds": 1.0,
    "ms": 1e-3,
    "msec": 1e-3,
    "us": 1e-6,
    "µs": 1e-6,
    "min": 60.0,
    "mins": 60.0,
    "minute": 60.0,
    "minutes": 60.0,
    "h": 3600.0,
    "hour": 3600.0,
    "hours": 3600.0,
}

_BANDWIDTH_FORMS = (
    "a number with a unit such as 56kbit, 56kbit/s, 56kbps, 7kB/s, 1.5Mbit/s or 2MiB/s "
    "(k=1000, Ki=1024; b or bit = bits, B = bytes), or a plain number of bit/s"
)
_DURATION_FORMS = (
    "a number with a unit such as 200ms, 0.5s, 10s or 1min, or a plain number of seconds"
)
_SIZE_FORMS = (
    "a number with a unit such as 512kB, 64MB, 64MiB or 1GB (k=1000, Ki=1024), "
    "or a plain number of bytes"
)


def _split(text: str | float, what: str, forms: str) -> tuple[float, str]:
    """Split ``text`` into a finite, non-negative number and its unit string."""
    if isinstance(text, bool):
        raise InputError(f"{what} {text!r} is not understood; use {forms}")
    if isinstance(text, int | float):
        value, unit = float(text), ""
        if not math.isfinite(value):
            raise InputError(f"{what} {text!r} is not a finite number; use {forms}")
    else:
        match = _QUANTITY.match(str(text))
        if match is None:
            raise InputError(f"{what} {text!r} is not understood; use {forms}")
        value, unit = float(match.group(1)), match.group(2)
        if not math.isfinite(value):  # e.g. "1e999"
            raise InputError(f"{what} {text!r} is not a finite number; use {forms}")
    if value < 0:
        raise InputError(f"{what} {text!r} is negative; use {forms}")
    return value, unit


def _prefixed(unit: str, bases: tuple[str, ...]) -> float | None:
    """The prefix multiplier of ``unit`` when it ends in one of ``bases``, else None."""
    for base in bases:
        if unit.endswith(base):
            prefix = unit[: -len(base)]
            if prefix in _PREFIXES:
                return _PREFIXES[prefix]
    return None


def parse_bandwidth(text: str | float) -> float:
    """Parse a link bandwidth into bits per second.

    Parameters
    ----------
    text
        ``"56kbit"``, ``"56kbit/s"``, ``"56kbps"``, ``"7kB/s"``, ``"1.5 Mbit/s"``,
        ``"0"``, ... A plain number is bits per second.

    Returns
    -------
    float
        Bits per second, finite and >= 0.

    Raises
    ------
    InputError
        For negative, non-finite or unreadable values; the message names the text and
        the accepted forms.

    Examples
    --------
    >>> parse_bandwidth("56kbit"), parse_bandwidth("7kB/s"), parse_bandwidth("1Mbit")
    (56000.0, 56000.0, 1000000.0)
    """
    value, unit = _split(text, "bandwidth", _BANDWIDTH_FORMS)
    if unit == "":
        return value
    rate = unit
    for suffix in _RATE_SUFFIXES:
        if rate.endswith(suffix) and len(rate) > len(suffix):
            rate = rate[: -len(suffix)]
            break
    bits = _prefixed(rate, _BIT_BASES)
    if bits is not None:
        return value * bits
    octets = _prefixed(rate, _BYTE_BASES)
    if octets is not None:
        return value * octets * 8.0
    raise InputError(f"bandwidth {text!r} has an unknown unit {unit!r}; use {_BANDWIDTH_FORMS}")


def parse_duration(text: str | float) -> float:
    """Parse a duration into seconds.

    Parameters
    ----------
    text
        ``"200ms"``, ``"0.5s"``, ``"500 ms"``, ``"1min"``, ... A plain number is seconds.

    Returns
    -------
    float
        Seconds, finite and >= 0.

    Raises
    ------
    InputError
        For negative, non-finite or unreadable values.

    Examples
    --------
    >>> parse_duration("200ms"), parse_duration("1min"), parse_duration("2")
    (0.2, 60.0, 2.0)
    """
    value, unit = _split(text, "duration", _DURATION_FORMS)
    scale = _DURATIONS.get(unit)
    if scale is None:
        raise InputError(f"duration {text!r} has an unknown unit {unit!r}; use {_DURATION_FORMS}")
    return value * scale


def parse_size(text: str | int) -> int:
    """Parse a size in bytes.

    Parameters
    ----------
    text
        ``"64MB"``, ``"64MiB"``, ``"512kB"``, ``"1GB"``, ``"64M"``, or a plain number of
        bytes.

    Returns
    -------
    int
        Bytes, >= 0.

    Raises
    ------
    InputError
        For negative, non-finite, fractional-byte or unreadable values.

    Examples
    --------
    >>> parse_size("64MB"), parse_size("64MiB"), parse_size("512kB")
    (64000000, 67108864, 512000)
    """
    value, unit = _split(text, "size", _SIZE_FORMS)
    if unit in _PREFIXES:  # "64M": a size can only be bytes
        scale: float | None = _PREFIXES[unit]
    else:
        scale = _prefixed(unit, _BYTE_BASES)
    if scale is None:
        raise InputError(f"size {text!r} has an unknown unit {unit!r}; use {_SIZE_FORMS}")
    total = value * scale
    whole = round(total)
    if abs(total - whole) > 1e-9 * max(1.0, total):
        raise InputError(f"size {text!r} is not a whole number of bytes; use {_SIZE_FORMS}")
    return int(whole)


def _scaled(value: float, steps: tuple[tuple[float, str], ...], base: str) -> str:
    """``value`` with the largest SI prefix from ``steps`` that keeps it >= 1."""
    if not math.isfinite(value):
        return f"{value} {base}"
    for scale, prefix in steps:
        if abs(value) >= scale:
            # 4 significant digits never switch to exponent notation below 1000
            return f"{value / scale:.4g} {prefix}{base}"
    return f"{value:.4g} {base}"


_SI_STEPS = ((1e9, "G"), (1e6, "M"), (1e3, "k"))


def format_bandwidth(bps: float) -> str:
    """A short label for a bandwidth in bits per second, e.g. ``"56 kbit/s"``.

    The label parses back with :func:`parse_bandwidth` (to 4 significant digits).
    """
    return _scaled(float(bps), _SI_STEPS, "bit/s")


def format_bytes(n: float) -> str:
    """A short label for a byte count with SI prefixes, e.g. ``"1.5 MB"``, ``"512 B"``.

    The label parses back with :func:`parse_size` (to 4 significant digits).
    """
    return _scaled(float(n), _SI_STEPS, "B")


def format_duration(seconds: float) -> str:
    """A short label for a duration: ``"200 ms"`` below one second, else ``"1.5 s"``."""
    seconds = float(seconds)
    if math.isfinite(seconds) and abs(seconds) < 1.0 and seconds != 0.0:
        return f"{seconds * 1e3:.4g} ms"
    return f"{seconds:.4g} s"
