"""``sdk.depth_edges``: the ``depth.edge`` input plane, defined once in the SDK."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rtp import sdk


def _plane_depth(h: int, w: int, a: float, b: float, c: float) -> np.ndarray:
    """Linear depth of a plane seen through a pinhole: inverse depth is affine in the pixel position
    (kept in front of the camera: a x + b y + c > 0.08 over the frame)."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    return (1.0 / (a * x + b * y + c)).astype(np.float32)


@settings(max_examples=30, deadline=None)
@given(a=st.floats(-0.004, 0.004), b=st.floats(-0.004, 0.004), c=st.floats(0.3, 1.0))
def test_planes_read_zero_at_any_slope(a: float, b: float, c: float) -> None:
    d = _plane_depth(24, 32, a, b, c)
    e = sdk.depth_edges(d)
    assert e.dtype == np.float32 and e.shape == d.shape
    assert e.max() < 1e-3, "a plane has no depth discontinuity"


def test_a_step_reads_one_minus_the_depth_ratio_on_both_sides() -> None:
    d = np.full((8, 10), 2.0, np.float32)
    d[:, 5:] = 8.0  # a wall at 2 in front of one at 8
    e = sdk.depth_edges(d)
    np.testing.assert_allclose(e[:, 4], 1 - 2 / 8, rtol=1e-6)
    np.testing.assert_allclose(e[:, 5], 1 - 2 / 8, rtol=1e-6)
    assert np.all(e[:, :4] == 0) and np.all(e[:, 6:] == 0)


def test_silhouettes_against_background_read_one() -> None:
    d = np.zeros((9, 9), np.float32)
    d[3:6, 3:6] = 5.0
    e = sdk.depth_edges(d)
    assert e[4, 4] == 0.0, "inside the object"
    assert e[4, 3] == 1.0 and e[4, 2] == 1.0, "both sides of the silhouette"
    assert e[0, 0] == 0.0, "open background"
    assert e.min() >= 0 and e.max() <= 1


def test_the_plane_does_not_depend_on_the_scene_scale_or_resolution_of_a_step() -> None:
    d = np.full((6, 12), 3.0, np.float32)
    d[:, 6:] = 4.5
    np.testing.assert_allclose(sdk.depth_edges(d), sdk.depth_edges(100 * d), rtol=1e-5)
    big = np.repeat(np.repeat(d, 2, 0), 2, 1)
    assert sdk.depth_edges(big).max() == pytest.approx(sdk.depth_edges(d).max(), rel=1e-6)


def test_it_is_a_registered_channel() -> None:
    c = sdk.CHANNELS["depth.edge"]
    assert (c.low, c.high) == (0.0, 1.0)


@pytest.mark.parametrize("bad, error", [
    (np.zeros((2, 3, 1), np.float32), sdk.InputShapeError),
    (np.zeros((0, 3), np.float32), sdk.InputShapeError),
    (np.array([["a", "b"]]), sdk.InputShapeError),
    (np.array([[1.0, np.nan]], np.float32), sdk.NonFiniteInputError),
    (np.array([[1.0, 2.0 + 1j, 3.0]]), sdk.InputShapeError),  # (its imaginary parts dropped in silence before)
], ids=["3-d", "empty", "strings", "nan", "complex"])
def test_bad_depth_is_a_typed_error(bad: np.ndarray, error: type[Exception]) -> None:
    with pytest.raises(error, match="depth_edges"):
        sdk.depth_edges(bad)
