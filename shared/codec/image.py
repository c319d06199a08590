"""Impostor images: premultiplied RGBA in memory, straight-alpha WebP (or AVIF) on the wire.

The bake renders an object over a transparent black background and averages
supersamples, which gives *premultiplied* colour (a silhouette texel half covered
holds half the object's colour and alpha 0.5).  Image files store straight alpha, so
:func:`encode_image` divides the colour by alpha first (texels with alpha 0 get
colour 0, which both WebP and AVIF are then free to drop), and :func:`decode_image`
multiplies it again.  The client filters and blends the premultiplied texels
(``ONE, ONE_MINUS_SRC_ALPHA``): filtering straight alpha would mix the black of the
transparent texels into the silhouette, the dark fringe.

The codecs (see docs/formats.md, "impostor images", for the measurement behind the
default): ``webp-lossless`` (the default), ``webp`` (lossy at ``quality``) and
``avif`` (lossy, when Pillow has it).  Decoding is bounded: the blob's size and the
image's dimensions are checked before Pillow decodes the pixels.
"""

from __future__ import annotations

import io

import numpy as np
from numpy.typing import NDArray

from walkstream.shared.errors import CodecError, InputError

__all__ = [
    "IMAGE_CODECS",
    "IMAGE_MEDIA",
    "MAX_IMAGE_BYTES",
    "MAX_IMAGE_SIDE",
    "decode_image",
    "encode_image",
    "premultiply",
    "unpremultiply",
]

IMAGE_CODECS: tuple[str, ...] = ("webp-lossless", "webp", "avif")
"""The image codecs :func:`encode_image` knows."""

IMAGE_MEDIA: dict[str, str] = {"webp-lossless": "image/webp", "webp": "image/webp", "avif": "image/avif"}
"""Media type of each codec's files."""

MAX_IMAGE_SIDE = 1024
"""The largest image side a decoder accepts, texels."""

MAX_IMAGE_BYTES = 4 << 20
"""The largest image blob a decoder accepts, bytes."""


def unpremultiply(rgba: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Straight alpha from premultiplied ``(h, w, 4) uint8`` (colour 0 where alpha is 0)."""
    a = rgba[..., 3:4].astype(np.float32)
    rgb = rgba[..., :3].astype(np.float32) * 255.0 / np.maximum(a, 1.0)
    rgb = np.where(a > 0, np.clip(np.rint(rgb), 0, 255), 0)
    return np.concatenate([rgb.astype(np.uint8), rgba[..., 3:4]], axis=-1)


def premultiply(rgba: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Premultiplied alpha from straight ``(h, w, 4) uint8``."""
    a = rgba[..., 3:4].astype(np.float32) / 255.0
    rgb = np.rint(rgba[..., :3].astype(np.float32) * a)
    return np.concatenate([rgb.astype(np.uint8), rgba[..., 3:4]], axis=-1)


def encode_image(rgba: NDArray[np.uint8], codec: str = "webp-lossless", quality: int = 90) -> bytes:
    """A premultiplied ``(h, w, 4) uint8`` image (row 0 at the top) as file bytes.

    Raises
    ------
    InputError
        An unknown codec, a codec this Pillow lacks, or not an ``(h, w, 4)`` image.
    """
    from PIL import Image, features

    if codec not in IMAGE_CODECS:
        raise InputError(f"image codec {codec!r}: expected one of {', '.join(IMAGE_CODECS)}")
    a = np.asarray(rgba)
    if a.ndim != 3 or a.shape[2] != 4 or a.dtype != np.uint8:
        raise InputError(f"encode_image: expected an (h, w, 4) uint8 image, got {a.shape} {a.dtype}")
    img = Image.fromarray(np.ascontiguousarray(unpremultiply(a)), "RGBA")
    out = io.BytesIO()
    if codec == "avif":
        if not features.check("avif"):
            raise InputError("image codec avif: this Pillow has no AVIF support")
        img.save(out, format="AVIF", quality=quality)
    elif codec == "webp":
        img.save(out, format="WEBP", quality=quality, method=4, exact=False)
    else:
        img.save(out, format="WEBP", lossless=True, quality=50, method=2, exact=False)
    return out.getvalue()


def decode_image(data: bytes, what: str) -> NDArray[np.uint8]:
    """The premultiplied ``(h, w, 4) uint8`` image of a blob (bounded).

    Raises
    ------
    CodecError
        Not bytes, too large, not a WebP/AVIF image, or over :data:`MAX_IMAGE_SIDE`.
    """
    from PIL import Image

    if not isinstance(data, bytes | bytearray | memoryview) or not 0 < len(data) <= MAX_IMAGE_BYTES:
        raise CodecError(f"{what}: expected an image of 1..{MAX_IMAGE_BYTES} bytes")
    try:
        with Image.open(io.BytesIO(bytes(data)), formats=["WEBP", "AVIF"]) as img:
            w, h = img.size
            if not (0 < w <= MAX_IMAGE_SIDE and 0 < h <= MAX_IMAGE_SIDE):
                raise CodecError(f"{what}: image of {w}x{h}, expected sides of 1..{MAX_IMAGE_SIDE}")
            rgba = np.asarray(img.convert("RGBA"), np.uint8)
    except CodecError:
        raise
    except Exception as exc:  # Pillow raises many kinds on bad bytes
        raise CodecError(f"{what}: not a WebP or AVIF image ({type(exc).__name__})") from exc
    return premultiply(rgba)
