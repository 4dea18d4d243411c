"""sRGB files say so, and reading honours it: ccjax's sRGB outputs are tagged (a PNG's ``sRGB``
chunk, a TIFF's and a JPEG's ICC profile, a JPEG's EXIF ColorSpace); a tagged file is refused as
linear input unless ``decode_srgb`` (or ``assume_linear``); ``decode_srgb`` decodes only
sRGB-encoded files, never an untagged 16-bit one; a JPEG output carries its input's EXIF with
Orientation 1 and upright pixels."""

from __future__ import annotations

import io as bytes_io
import struct
import zlib

import numpy as np
import pytest
import tifffile
from PIL import Image, ImageCms

from ccjax import cli, io
from ccjax.io.icc import icc_encoding
from ccjax.io.jpeg import upright_exif

EXIF_IFD, ORIENTATION, MAKE, MODEL, DATE_ORIGINAL, COLOR_SPACE = 0x8769, 0x0112, 0x010F, 0x0110, 0x9003, 0xA001
ICC_TAG = 34675  # TIFF's InterColorProfile


def _srgb_decoded(codes: np.ndarray, maximum: float) -> np.ndarray:
    """Oracle: the IEC 61966-2-1 decoding curve written out."""
    v = codes.astype(np.float64) / maximum
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _chunks(blob: bytes) -> list[tuple[bytes, bytes]]:
    """``(type, data)`` of every chunk of a PNG, each CRC checked."""
    assert blob[:8] == b"\x89PNG\r\n\x1a\n"
    chunks, position = [], 8
    while position < len(blob):
        (length,) = struct.unpack(">I", blob[position : position + 4])
        kind, data = blob[position + 4 : position + 8], blob[position + 8 : position + 8 + length]
        (crc,) = struct.unpack(">I", blob[position + 8 + length : position + 12 + length])
        assert crc == zlib.crc32(kind + data)
        chunks.append((kind, data))
        position += 12 + length
    return chunks


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _pillow_srgb_profile() -> bytes:
    return ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()


def _profile(name: str, curve: bytes) -> bytes:
    """A v2 display profile written from ICC.1: a ``desc`` tag, sRGB's D50 colorants, and
    ``curve`` (a whole ``curv`` tag) as the three tone curves."""

    def xyz(*values: float) -> bytes:
        return b"XYZ \0\0\0\0" + struct.pack(">3i", *(round(v * 65536) for v in values))

    text = name.encode() + b"\0"
    desc = b"desc\0\0\0\0" + struct.pack(">I", len(text)) + text + bytes(4 + 4 + 2 + 1 + 67)
    tags = [
        (b"desc", desc),
        (b"rXYZ", xyz(0.4361, 0.2225, 0.0139)),
        (b"gXYZ", xyz(0.3851, 0.7169, 0.0971)),
        (b"bXYZ", xyz(0.1431, 0.0606, 0.7141)),
        (b"rTRC", curve),
        (b"gTRC", curve),
        (b"bTRC", curve),
    ]
    offset, table, data = 132 + 12 * len(tags), b"", b""
    for signature, body in tags:
        body += bytes(-len(body) % 4)
        table += struct.pack(">4sII", signature, offset + len(data), len(body))
        data += body
    size = offset + len(data)
    header = struct.pack(">I4sI4s4s4s", size, b"none", 0x02100000, b"mntr", b"RGB ", b"XYZ ")
    header += bytes(12) + b"acsp" + bytes(128 - 40)
    return header + struct.pack(">I", len(tags)) + table + data


def _curv(values: np.ndarray) -> bytes:
    return b"curv\0\0\0\0" + struct.pack(">I", len(values)) + values.astype(">u2").tobytes()


def test_an_srgb_png_has_an_srgb_chunk_before_its_data_and_a_linear_one_none(tmp_path):
    codes = np.random.default_rng(1).integers(0, 65535, (6, 5, 3)).astype(np.uint16)
    io.write_png(tmp_path / "srgb.png", codes, srgb=True)
    io.write_png(tmp_path / "linear.png", codes)
    kinds = [kind for kind, _ in _chunks((tmp_path / "srgb.png").read_bytes())]
    assert kinds.count(b"sRGB") == 1 and kinds.index(b"sRGB") < kinds.index(b"IDAT")
    assert dict(_chunks((tmp_path / "srgb.png").read_bytes()))[b"sRGB"] == b"\x00"  # perceptual intent
    linear = [kind for kind, _ in _chunks((tmp_path / "linear.png").read_bytes())]
    assert not {b"sRGB", b"iCCP", b"gAMA"} & set(linear)
    np.testing.assert_array_equal(io.read_png(tmp_path / "srgb.png"), codes)


def test_an_srgb_jpeg_carries_the_srgb_profile_and_exif_colour_space_1(tmp_path):
    rng = np.random.default_rng(2)
    codes = np.repeat(np.repeat(rng.integers(20, 235, (2, 3, 3)), 16, 0), 16, 1).astype(np.uint8)
    io.write_codes(tmp_path / "out.jpg", codes, srgb=True)
    with Image.open(tmp_path / "out.jpg") as image:
        profile = image.info["icc_profile"]
        exif = image.getexif()
        pixels = np.asarray(image)
    assert "sRGB" in ImageCms.getProfileDescription(ImageCms.ImageCmsProfile(bytes_io.BytesIO(profile)))
    assert profile[16:20] == b"RGB " and profile[36:40] == b"acsp"
    assert exif.get_ifd(EXIF_IFD)[COLOR_SPACE] == 1
    # Quality 95 of flat 16 x 16 blocks: the blocks' insides are the codes (their edges take the
    # chroma upsampling's blur).
    inside = (np.arange(32)[:, None] % 16 - 7.5) ** 2 + (np.arange(48)[None] % 16 - 7.5) ** 2 < 20
    assert np.abs(pixels[inside].astype(float) - codes[inside]).max() <= 2
    io.write_codes(tmp_path / "plain.jpg", codes)  # not sRGB: no profile, no colour space claimed
    with Image.open(tmp_path / "plain.jpg") as image:
        assert "icc_profile" not in image.info and COLOR_SPACE not in image.getexif().get_ifd(EXIF_IFD)


def test_an_srgb_tiff_carries_the_profile_and_a_linear_one_none(tmp_path):
    codes = np.full((4, 4, 3), 30000, np.uint16)
    io.write_codes(tmp_path / "srgb.tif", codes, srgb=True)
    io.write_codes(tmp_path / "linear.tif", codes)
    with tifffile.TiffFile(tmp_path / "srgb.tif") as tif:
        profile = tif.pages.first.tags[ICC_TAG].value
    assert profile[16:20] == b"RGB " and profile[36:40] == b"acsp"
    with tifffile.TiffFile(tmp_path / "linear.tif") as tif:
        assert ICC_TAG not in tif.pages.first.tags


def _png_with(blob: bytes, chunk: bytes) -> bytes:
    return blob[:33] + chunk + blob[33:]  # after the signature and IHDR


def test_tagged_16_bit_files_are_refused_without_decode_and_decoded_with_it(tmp_path):
    """An ``sRGB`` chunk, an sRGB ``iCCP`` profile, an sRGB TIFF profile: refused as linear (the
    message names the file and both options), decoded by the IEC 61966-2-1 curve with
    ``decode_srgb``, read as the codes with ``assume_linear``."""
    codes = np.random.default_rng(3).integers(1, 60000, (8, 9, 3)).astype(np.uint16)
    io.write_png(tmp_path / "chunk.png", codes, srgb=True)
    io.write_png(tmp_path / "plain.png", codes)
    iccp = b"sRGB\0\0" + zlib.compress(_pillow_srgb_profile())
    (tmp_path / "iccp.png").write_bytes(_png_with((tmp_path / "plain.png").read_bytes(), _chunk(b"iCCP", iccp)))
    tifffile.imwrite(tmp_path / "icc.tif", codes, photometric="rgb", iccprofile=_pillow_srgb_profile())
    for name in ("chunk.png", "iccp.png", "icc.tif"):
        path = tmp_path / name
        for call in (io.probe_image, io.read_image):
            with pytest.raises(ValueError, match=rf"{name} is tagged sRGB.*--decode-srgb.*--assume-linear"):
                call(path)
        assert (io.probe_image(path, decode_srgb=True).encoding or "").startswith("sRGB")
        decoded = io.read_image(path, decode_srgb=True)
        np.testing.assert_allclose(decoded.rgb, _srgb_decoded(codes, 65535), rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(io.read_image(path, assume_linear=True).rgb, codes / 65535, rtol=1e-6)


def test_an_untagged_16_bit_file_reads_the_same_with_and_without_decode_srgb(tmp_path):
    codes = np.random.default_rng(4).integers(1, 60000, (8, 9, 3)).astype(np.uint16)
    io.write_png(tmp_path / "linear.png", codes)
    tifffile.imwrite(tmp_path / "float.tif", (codes / 65535).astype(np.float32), photometric="rgb")
    for name in ("linear.png", "float.tif"):
        plain = io.read_image(tmp_path / name)
        decoded = io.read_image(tmp_path / name, decode_srgb=True)
        np.testing.assert_array_equal(decoded.rgb, plain.rgb)
        np.testing.assert_allclose(plain.rgb, codes / 65535, rtol=1e-6)
        assert io.probe_image(tmp_path / name, decode_srgb=True).encoding is None


def test_icc_profiles_are_judged_by_their_curves_and_primaries(tmp_path):
    """A v2 sRGB profile (a 1024-entry curve table) is sRGB; the same primaries with the identity
    curve ("linear sRGB", as raw developers embed) are linear, and such a TIFF is read as its
    codes; a cut-short or garbage profile is no profile (never an exception)."""
    grid = np.linspace(0, 1, 1024)
    srgb_curve = np.round(_srgb_decoded(np.round(grid * 65535), 65535) * 65535)
    encoded = _profile("sRGB IEC61966-2.1", _curv(srgb_curve))
    assert icc_encoding(encoded) == "sRGB (ICC profile 'sRGB IEC61966-2.1')"
    assert icc_encoding(_profile("Display", _curv(srgb_curve))) == "sRGB (ICC profile 'Display')"  # primaries
    linear = _profile("Linear sRGB", _curv(np.array([], np.uint16)))
    assert icc_encoding(linear) is None
    assert icc_encoding(_profile("sRGB gamma 1", _curv(np.array([256])))) is None
    codes = np.full((4, 4, 3), 30000, np.uint16)
    tifffile.imwrite(tmp_path / "linear.tif", codes, photometric="rgb", iccprofile=linear)
    np.testing.assert_allclose(io.read_image(tmp_path / "linear.tif").rgb, 30000 / 65535, rtol=1e-6)
    rng = np.random.default_rng(5)
    for cut in range(0, len(encoded), 7):
        assert icc_encoding(encoded[:cut]) in (None, "sRGB (ICC profile 'sRGB IEC61966-2.1')")
        noisy = bytearray(encoded)
        noisy[cut] = int(rng.integers(256))
        icc_encoding(bytes(noisy))


def _oriented_jpeg(path, stored: np.ndarray) -> None:
    """A JPEG of ``stored`` pixels tagged Orientation 6, with camera and time tags."""
    exif = Image.Exif()
    exif[ORIENTATION], exif[MAKE], exif[MODEL] = 6, "Canon", "EOS R5"
    exif[EXIF_IFD] = {DATE_ORIGINAL: "2024:05:06 07:08:09"}
    Image.fromarray(stored).save(path, "JPEG", quality=95, exif=exif.tobytes())


def _quadrants() -> np.ndarray:
    """``(32, 48, 3)`` stored pixels: four flat quadrants of distinct colours."""
    stored = np.empty((32, 48, 3), np.uint8)
    stored[:16, :24], stored[:16, 24:] = (220, 30, 30), (30, 220, 30)
    stored[16:, :24], stored[16:, 24:] = (30, 30, 220), (200, 200, 200)
    return stored


def test_a_jpeg_output_carries_its_inputs_exif_upright(tmp_path):
    stored = _quadrants()
    _oriented_jpeg(tmp_path / "in.jpg", stored)
    upright = np.rot90(stored, k=-1)  # EXIF 6: rotate 90 degrees clockwise to view
    image = io.read_image(tmp_path / "in.jpg", decode_srgb=True)
    assert image.shape == upright.shape[:2]
    codes = io.encode_srgb(image.rgb, 8)  # back to sRGB codes: the pixels ccjax would write
    io.write_codes(tmp_path / "out.jpg", codes, srgb=True, exif=upright_exif(tmp_path / "in.jpg"))
    with Image.open(tmp_path / "out.jpg") as out:
        exif = out.getexif()
        pixels = np.asarray(out)
    assert exif[ORIENTATION] == 1 and exif[MAKE] == "Canon" and exif[MODEL] == "EOS R5"
    assert exif.get_ifd(EXIF_IFD)[DATE_ORIGINAL] == "2024:05:06 07:08:09"
    assert exif.get_ifd(EXIF_IFD)[COLOR_SPACE] == 1
    assert pixels.shape == upright.shape
    # Away from the quadrants' edges (JPEG blocks blur them), the colours are where upright has them.
    for rows in (slice(4, 20), slice(28, 44)):
        for cols in (slice(3, 12), slice(20, 29)):
            assert np.abs(pixels[rows, cols].mean((0, 1)) - upright[rows, cols].mean((0, 1))).max() < 6


def test_a_tiffs_exif_is_carried_and_an_oversized_maker_note_dropped(tmp_path):
    """A TIFF's camera tags reach the JPEG output; a maker note too big for a JPEG's APP1 segment
    (65533 bytes) is left out, the rest kept."""
    exif = Image.Exif()
    exif[ORIENTATION], exif[MAKE], exif[MODEL] = 8, "Nikon", "Z 8"
    exif[EXIF_IFD] = {DATE_ORIGINAL: "2023:01:02 03:04:05", 0x927C: b"m" * 70000}
    Image.fromarray(_quadrants()).save(tmp_path / "in.tif", exif=exif.tobytes())
    carried = upright_exif(tmp_path / "in.tif")
    assert carried is not None and len(carried) < 65533
    io.write_codes(tmp_path / "out.jpg", _quadrants(), srgb=True, exif=carried)
    with Image.open(tmp_path / "out.jpg") as out:
        tags = out.getexif()
    assert (tags[ORIENTATION], tags[MAKE], tags[MODEL]) == (1, "Nikon", "Z 8")
    assert tags.get_ifd(EXIF_IFD)[DATE_ORIGINAL] == "2023:01:02 03:04:05" and 0x927C not in tags.get_ifd(EXIF_IFD)


def test_a_multi_picture_jpeg_reads_as_its_primary_image(tmp_path):
    """Cameras append previews to a JPEG (CIPA DC-007 multi-picture format; Pillow calls it MPO):
    the first image is the photograph."""
    primary = Image.fromarray(_quadrants())
    primary.save(tmp_path / "mpo.jpg", "MPO", save_all=True, append_images=[Image.new("RGB", (8, 6))])
    with Image.open(tmp_path / "mpo.jpg") as check:
        assert check.format == "MPO"
    image = io.read_image(tmp_path / "mpo.jpg", decode_srgb=True)
    assert image.shape == (32, 48)
    np.testing.assert_allclose(
        image.rgb[4:12, 4:20].mean((0, 1)), _srgb_decoded(np.array([220, 30, 30]), 255), atol=0.02
    )


def test_a_file_without_exif_gives_none(tmp_path):
    Image.fromarray(_quadrants()).save(tmp_path / "bare.jpg", "JPEG")
    io.write_png(tmp_path / "linear.png", np.full((4, 4, 3), 100, np.uint16))
    assert upright_exif(tmp_path / "bare.jpg") is None
    assert upright_exif(tmp_path / "linear.png") is None
    assert upright_exif(tmp_path / "absent.jpg") is None


def test_correct_jpeg_to_srgb_jpeg_end_to_end(plain_preview_commands, capsys):
    """``ccjax correct in.jpg out.jpg --decode-srgb --srgb 8``: the output carries the sRGB profile,
    ColorSpace 1 and the input's camera tags with Orientation 1, its preview an ``sRGB`` chunk, and
    ccjax refuses to read it back as linear; ``--srgb 16`` TIFF output likewise, decoded with
    ``--decode-srgb``."""
    folder = plain_preview_commands
    stored = _quadrants()
    _oriented_jpeg(folder / "in.jpg", stored)
    base = ["correct", str(folder / "in.jpg")]
    options = ["--decode-srgb", "--method", "GW", "--no-progress"]
    preview = ["--preview", str(folder / "preview.png")]
    assert cli.main([*base, str(folder / "out.jpg"), *options, *preview, "--srgb", "8"]) == 0
    with Image.open(folder / "out.jpg") as out:
        exif, profile, size = out.getexif(), out.info["icc_profile"], out.size
    assert size == (32, 48)  # (width, height): upright
    assert exif[ORIENTATION] == 1 and exif[MAKE] == "Canon" and exif[MODEL] == "EOS R5"
    assert exif.get_ifd(EXIF_IFD)[DATE_ORIGINAL] == "2024:05:06 07:08:09"
    assert exif.get_ifd(EXIF_IFD)[COLOR_SPACE] == 1 and profile[16:20] == b"RGB "
    assert b"sRGB" in [kind for kind, _ in _chunks((folder / "preview.png").read_bytes())]
    with pytest.raises(ValueError, match=r"out\.jpg is 8-bit.*--decode-srgb"):
        io.read_image(folder / "out.jpg")
    preview = ["--preview", str(folder / "preview16.png")]
    assert cli.main([*base, str(folder / "out16.tif"), *options, *preview, "--srgb", "16"]) == 0
    with pytest.raises(ValueError, match=r"out16\.tif is tagged sRGB \(ICC profile .*--decode-srgb"):
        io.read_image(folder / "out16.tif")
    capsys.readouterr()
    assert cli.main(["estimate", str(folder / "out16.tif"), "--method", "GW", "--no-progress"]) != 0
    assert "out16.tif is tagged sRGB" in capsys.readouterr().err
    assert cli.main(["estimate", str(folder / "out16.tif"), "--method", "GW", "--decode-srgb", "--no-progress"]) == 0
