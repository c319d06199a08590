"""Parsing and formatting of bandwidths, durations and sizes (client.units)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from walkstream.client.units import (
    format_bandwidth,
    format_bytes,
    format_duration,
    parse_bandwidth,
    parse_duration,
    parse_size,
)
from walkstream.shared.errors import InputError


@pytest.mark.parametrize(
    ("text", "bps"),
    [
        ("56kbit", 56_000),
        ("56kbit/s", 56_000),
        ("56kbps", 56_000),
        ("56Kbps", 56_000),
        ("56 kb/s", 56_000),
        ("7kB/s", 56_000),
        ("7KB/s", 56_000),
        ("7 kBps", 56_000),
        ("5kB/s", 40_000),
        ("1Mbit", 1_000_000),
        ("1mbit", 1_000_000),
        ("1.5 Mbit/s", 1_500_000),
        ("2Gbit/s", 2e9),
        ("1KiB/s", 8 * 1024),
        ("1Mibit", 1024**2),
        ("1MiB/s", 8 * 1024**2),
        ("100bit", 100),
        ("100bits/s", 100),
        ("100bps", 100),
        ("12B/s", 96),
        ("0", 0),
        ("0bit", 0),
        ("56000", 56_000),
        ("  2.5e3 ", 2500),
        (".5kbit", 500),
        (9600, 9600),
        (1.5, 1.5),
    ],
)
def test_parse_bandwidth(text: str | float, bps: float) -> None:
    assert parse_bandwidth(text) == pytest.approx(bps, rel=1e-12)
    assert isinstance(parse_bandwidth(text), float)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("-5kbit", "negative"),
        ("nan", "not understood"),
        ("inf", "not understood"),
        ("1e999", "finite"),
        (float("inf"), "finite"),
        (float("nan"), "finite"),
        ("", "not understood"),
        ("fast", "not understood"),
        ("56 kbit extra", "not understood"),
        ("56kbit/h", "unknown unit"),
        ("56k", "unknown unit"),
        ("56ps", "unknown unit"),
        ("56xbit", "unknown unit"),
        ("1,5Mbit", "not understood"),
        (True, "not understood"),
    ],
)
def test_parse_bandwidth_refuses(text: str | float, needle: str) -> None:
    with pytest.raises(InputError, match=needle) as info:
        parse_bandwidth(text)
    message = str(info.value)
    assert repr(text) in message  # names the bad text
    assert "56kbit" in message and "7kB/s" in message  # and the accepted forms


@pytest.mark.parametrize(
    ("text", "seconds"),
    [
        ("200ms", 0.2),
        ("500 ms", 0.5),
        ("0.5s", 0.5),
        ("10s", 10.0),
        ("10 sec", 10.0),
        ("1min", 60.0),
        ("2 minutes", 120.0),
        ("1h", 3600.0),
        ("250us", 250e-6),
        ("3", 3.0),
        ("0", 0.0),
        (0.25, 0.25),
    ],
)
def test_parse_duration(text: str | float, seconds: float) -> None:
    assert parse_duration(text) == pytest.approx(seconds, rel=1e-12)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("-1s", "negative"),
        ("1 fortnight", "unknown unit"),
        ("soon", "not understood"),
        ("1m", "unknown"),
    ],
)
def test_parse_duration_refuses(text: str, needle: str) -> None:
    with pytest.raises(InputError, match=needle) as info:
        parse_duration(text)
    assert repr(text) in str(info.value) and "200ms" in str(info.value)


@pytest.mark.parametrize(
    ("text", "nbytes"),
    [
        ("64MB", 64_000_000),
        ("64MiB", 64 * 1024**2),
        ("64M", 64_000_000),
        ("512kB", 512_000),
        ("512KiB", 512 * 1024),
        ("1GB", 10**9),
        ("1.5GiB", 3 * 2**29),
        ("100 bytes", 100),
        ("100B", 100),
        ("4096", 4096),
        ("0", 0),
        (123, 123),
    ],
)
def test_parse_size(text: str | int, nbytes: int) -> None:
    got = parse_size(text)
    assert got == nbytes and isinstance(got, int)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("-1MB", "negative"),
        ("1.5B", "whole number"),
        ("64Mbit", "unknown unit"),
        ("64 MB!", "not understood"),
        ("lots", "not understood"),
    ],
)
def test_parse_size_refuses(text: str, needle: str) -> None:
    with pytest.raises(InputError, match=needle) as info:
        parse_size(text)
    assert repr(text) in str(info.value) and "64MiB" in str(info.value)


def test_errors_are_value_errors() -> None:
    # callers that only know built-ins still catch them
    with pytest.raises(ValueError):
        parse_bandwidth("quick")


@pytest.mark.parametrize(
    ("bps", "label"),
    [
        (0, "0 bit/s"),
        (300, "300 bit/s"),
        (56_000, "56 kbit/s"),
        (1_500_000, "1.5 Mbit/s"),
        (2e9, "2 Gbit/s"),
        (999_999, "1000 kbit/s"),
    ],
)
def test_format_bandwidth(bps: float, label: str) -> None:
    assert format_bandwidth(bps) == label


@pytest.mark.parametrize(
    ("n", "label"),
    [(0, "0 B"), (512, "512 B"), (7_000, "7 kB"), (1_500_000, "1.5 MB"), (64 * 10**9, "64 GB")],
)
def test_format_bytes(n: int, label: str) -> None:
    assert format_bytes(n) == label


def test_format_duration() -> None:
    assert format_duration(0.2) == "200 ms"
    assert format_duration(1.5) == "1.5 s"
    assert format_duration(0) == "0 s"


@given(st.floats(min_value=0, max_value=1e12, allow_nan=False))
def test_bandwidth_labels_parse_back(bps: float) -> None:
    assert parse_bandwidth(format_bandwidth(bps)) == pytest.approx(bps, rel=1e-3, abs=1e-3)


@given(st.integers(min_value=0, max_value=10**13))
def test_byte_labels_parse_back(n: int) -> None:
    # the label rounds to 4 significant digits
    assert parse_size(format_bytes(n)) == pytest.approx(n, rel=1e-3)
