"""Interoperability with OpenCV's white balance (``cv2.xphoto``, docs/getting-started.md): the same
grey-world estimate, and a ccjax estimate as OpenCV's channel gains and back.

OpenCV's ``GrayworldWB`` averages each channel over the pixels whose saturation
``(max - min) / max`` is below its threshold and applies the gains ``min(mean) / mean_c`` (the
largest gain 1). On an image with no zero channel and no clipped pixel both use every pixel."""

from __future__ import annotations

import numpy as np
import pytest

import ccjax

cv2 = pytest.importorskip("cv2", reason="opencv-contrib-python-headless (the test extra)")


def _angle(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0)))


@pytest.fixture(scope="module")
def photo():
    """A 16-bit RGB image with a colour cast, every channel in (0, saturation)."""
    rng = np.random.default_rng(7)
    rgb = rng.uniform(0.05, 0.6, (48, 64, 3)) * np.array([0.9, 0.7, 0.35])
    return np.round(rgb * 65535).astype(np.uint16)


def test_grey_world_is_the_same_estimate(photo):
    wb = cv2.xphoto.createGrayworldWB()
    wb.setSaturationThreshold(1.0)  # every pixel with no zero channel, as ccjax's usable pixels here
    balanced = wb.balanceWhite(np.ascontiguousarray(photo[..., ::-1]))[..., ::-1].astype(np.float64)
    # OpenCV returns the balanced image: its gains are the ratio out / in (to the output's rounding).
    opencv_gains = np.median(balanced / photo, axis=(0, 1))
    estimate = np.asarray(ccjax.estimate("GW", photo.reshape(-1, 3).astype(np.float32) / 65535).illuminant)
    # A ccjax estimate -> OpenCV's gains: min(e) / e (grey world's e is 2 x the mean RGB).
    gains = estimate.min() / estimate
    np.testing.assert_allclose(gains, opencv_gains, rtol=2e-4)
    # ... and back: the light is the inverse of the gains, up to scale.
    assert _angle(1.0 / opencv_gains, estimate) < 0.01


def test_a_ccjax_estimate_applied_by_opencv_matches_its_balance(photo):
    """Any ccjax estimate (here grey edge's) applied with ``cv2.xphoto.applyChannelGains`` (BGR
    order) gives the pixels ``photo * gains``, to OpenCV's fixed-point rounding."""
    image = photo.astype(np.float32) / 65535
    estimate = np.asarray(ccjax.estimate("grey-edge-1-6-2", image).illuminant, np.float64)
    gains = estimate.min() / estimate
    applied = cv2.xphoto.applyChannelGains(np.ascontiguousarray(photo[..., ::-1]), *gains[::-1])[..., ::-1]
    want = np.minimum(photo * gains, 65535)
    assert np.max(np.abs(applied.astype(np.float64) - want)) <= 2.0
