"""ICC colour profiles: does an embedded profile say the codes are sRGB-encoded, and the sRGB
profile ccjax embeds in its own sRGB outputs.

A profile is read here, not by LittleCMS: only a few tags are needed (the description, the
colorants and the tone curves, ICC.1:2010 §9.2), and a file's embedded profile is untrusted
input, so every offset is checked against the profile's length and nothing else is parsed.
"""

from __future__ import annotations

import functools
import struct

MAX_PROFILE_BYTES = 1 << 22
"""Largest embedded profile interpreted (4 MB; sRGB profiles take 0.5-3 kB, the largest
lookup-table profiles about 1 MB): a file claiming more is treated as untagged."""

SRGB_COLORANTS = {
    b"rXYZ": (0.4361, 0.2225, 0.0139),
    b"gXYZ": (0.3851, 0.7169, 0.0971),
    b"bXYZ": (0.1431, 0.0606, 0.7141),
}
"""sRGB's primaries as an ICC profile gives them: XYZ adapted to D50 by Bradford (IEC 61966-2-1
Amendment 1, the profile connection space's white)."""
COLORANT_TOLERANCE = 0.003
"""How far a colorant may be from :data:`SRGB_COLORANTS` (s15Fixed16 rounding and the slightly
different adaptations of common profiles stay well inside)."""
LINEAR_TOLERANCE = 0.01
"""How far a tone curve may be from the identity, on the unit scale, and still be linear."""

_PARAMETERS = {0: 1, 1: 3, 2: 4, 3: 5, 4: 7}  # 'para' function type -> parameters (ICC.1 Table 68)
_SAMPLES = (0.1, 0.25, 0.5, 0.75, 0.9)  # where a tone curve is compared with the identity


def _tags(profile: bytes) -> dict[bytes, bytes]:
    """Each tag's data, by signature; tags outside the profile are left out."""
    if len(profile) < 132:
        return {}
    (count,) = struct.unpack(">I", profile[128:132])
    tags = {}
    for index in range(min(count, (len(profile) - 132) // 12)):
        start = 132 + 12 * index
        signature, offset, size = struct.unpack(">4sII", profile[start : start + 12])
        if offset + size <= len(profile):
            tags[signature] = profile[offset : offset + size]
    return tags


def _description(data: bytes | None) -> str:
    """The text of a ``desc`` (v2 ``desc`` type, or v4 ``mluc``: its first record) tag, or ``""``."""
    if data is None or len(data) < 12:
        return ""
    if data[:4] == b"desc":
        (length,) = struct.unpack(">I", data[8:12])
        return data[12 : 12 + length].split(b"\0")[0].decode("latin-1")
    if data[:4] == b"mluc" and len(data) >= 28:
        length, offset = struct.unpack(">II", data[20:28])
        return data[offset : offset + length].decode("utf-16-be", "replace").rstrip("\0")
    return ""


def _parametric(kind: int, values: tuple[float, ...], x: float) -> float:
    """A ``para`` curve at ``x`` (ICC.1 Table 68; ``values`` = g, a, b, c, d, e, f as present)."""
    g, a, b, c, d, e, f = (*values, *(0.0,) * (7 - len(values)))
    if kind == 0:
        return x**g
    if kind in (1, 2):
        base = a * x + b
        return (base**g if base >= 0 else 0.0) + (c if kind == 2 else 0.0)
    if x < d:
        return c * x + (f if kind == 4 else 0.0)
    return max(a * x + b, 0.0) ** g + (e if kind == 4 else 0.0)


def _curve_is_linear(data: bytes | None) -> bool | None:
    """Whether a tone curve tag (``curv`` or ``para``) is the identity; None when unreadable."""
    if data is None or len(data) < 12:
        return None
    if data[:4] == b"curv":
        (count,) = struct.unpack(">I", data[8:12])
        if count == 0:
            return True  # the identity, by definition
        if len(data) < 12 + 2 * count:
            return None
        table = struct.unpack(f">{count}H", data[12 : 12 + 2 * count])
        if count == 1:
            return abs(table[0] / 256 - 1.0) < LINEAR_TOLERANCE  # a gamma, u8Fixed8
        values = [table[round(x * (count - 1))] / 65535 for x in _SAMPLES]
        points = [round(x * (count - 1)) / (count - 1) for x in _SAMPLES]
        return all(abs(v - p) < LINEAR_TOLERANCE for v, p in zip(values, points, strict=True))
    if data[:4] == b"para":
        (kind,) = struct.unpack(">H", data[8:10])
        size = _PARAMETERS.get(kind)
        if size is None or len(data) < 12 + 4 * size:
            return None
        values = tuple(v / 65536 for v in struct.unpack(f">{size}i", data[12 : 12 + 4 * size]))
        try:
            return all(abs(_parametric(kind, values, x) - x) < LINEAR_TOLERANCE for x in _SAMPLES)
        except (ArithmeticError, TypeError):  # a nonsense curve (0 ** negative, a complex power)
            return None
    return None


def _xyz(data: bytes | None) -> tuple[float, ...] | None:
    if data is None or len(data) < 20 or data[:4] != b"XYZ ":
        return None
    return tuple(v / 65536 for v in struct.unpack(">3i", data[8:20]))


def icc_encoding(profile: bytes) -> str | None:
    """What an ICC profile says about the codes, when it describes sRGB-encoded RGB: an RGB
    profile named sRGB or with sRGB's colorants, whose tone curves are not the identity (a
    "linear sRGB" profile, as raw developers embed in linear exports, describes linear data).

    Arguments:
        profile: the profile's bytes (a TIFF's tag 34675, a PNG's decompressed ``iCCP``).

    Returns:
        ``"sRGB (ICC profile '<description>')"``, or None (not sRGB, linear, not RGB, or not a
        readable profile).
    """
    if len(profile) < 132 or profile[16:20] != b"RGB ":
        return None
    tags = _tags(profile)
    name = _description(tags.get(b"desc"))
    colorants = [_xyz(tags.get(signature)) for signature in SRGB_COLORANTS]
    srgb_colorants = all(
        found is not None and all(abs(x - y) < COLORANT_TOLERANCE for x, y in zip(found, want, strict=True))
        for found, want in zip(colorants, SRGB_COLORANTS.values(), strict=True)
    )
    if not (srgb_colorants or "srgb" in name.lower()):
        return None
    linear = [_curve_is_linear(tags.get(signature)) for signature in (b"rTRC", b"gTRC", b"bTRC")]
    if all(linear):  # an unreadable or missing curve counts as sRGB's own: the name or colorants say sRGB
        return None
    return f"sRGB (ICC profile {name!r})" if name else "sRGB (ICC profile)"


_PROFILE_DATE = struct.pack(">6H", 2000, 1, 1, 0, 0, 0)
"""The creation date written into ccjax's sRGB profile (LittleCMS writes the current time, which
would make two runs' outputs differ)."""


@functools.cache
def srgb_profile() -> bytes:
    """The ICC profile ccjax embeds in its sRGB outputs: LittleCMS's sRGB (through Pillow; IEC
    61966-2-1's primaries, D65 white and parametric curve), with a fixed creation date.

    Returns:
        The profile's bytes (about 600).
    """
    from PIL import ImageCms

    profile = bytearray(ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes())
    profile[24:36] = _PROFILE_DATE
    profile[84:100] = bytes(16)  # a zero profile ID means "not computed" (an MD5 would cover the date)
    return bytes(profile)


__all__ = ["MAX_PROFILE_BYTES", "icc_encoding", "srgb_profile"]
