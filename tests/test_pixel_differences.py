"""``sdk.pixel_differences``: the ``reprojected.y.dx`` / ``.dy`` input planes, defined once in the SDK."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from rtp import sdk


@settings(max_examples=40, deadline=None)
@given(hnp.arrays(np.float32, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=12),
                  elements=st.floats(0, 1, width=32)))
def test_each_pixel_holds_its_difference_to_the_right_and_below(p: np.ndarray) -> None:
    dx, dy = sdk.pixel_differences(p)
    assert dx.dtype == dy.dtype == np.float32 and dx.shape == dy.shape == p.shape
    h, w = p.shape
    for y in range(h):
        for x in range(w):
            assert dx[y, x] == (abs(p[y, x + 1] - p[y, x]) if x + 1 < w else 0.0)
            assert dy[y, x] == (abs(p[y + 1, x] - p[y, x]) if y + 1 < h else 0.0)
    # a transpose swaps the two planes: what the 1x2 and 2x1 rates would lose
    tx, ty = sdk.pixel_differences(p.T)
    np.testing.assert_array_equal(tx, dy.T)
    np.testing.assert_array_equal(ty, dx.T)


def test_a_block_constant_plane_differs_only_between_blocks() -> None:
    blocks = np.repeat(np.repeat(np.random.default_rng(0).random((3, 4)), 2, axis=0), 2, axis=1)
    dx, dy = sdk.pixel_differences(blocks)
    assert not dx[:, 0::2].any() and not dy[0::2].any()  # inside each 2x2 block nothing to lose
    assert dx[:, 1:-1:2].any() and dy[1:-1:2].any()


def test_they_are_registered_channels() -> None:
    for c in ("reprojected.y.dx", "reprojected.y.dy"):
        spec = sdk.CHANNELS[c]
        assert (spec.low, spec.high) == (0.0, 1.0) and "pixel_differences" in spec.description


@pytest.mark.parametrize(("bad", "error"), [
    (np.zeros(5, np.float32), sdk.InputShapeError),
    (np.zeros((0, 3), np.float32), sdk.InputShapeError),
    (np.array([["a"]]), sdk.InputShapeError),
    (np.array([[0.0, np.nan]], np.float32), sdk.NonFiniteInputError),
])
def test_bad_planes_are_typed_errors(bad: np.ndarray, error: type[Exception]) -> None:
    with pytest.raises(error, match="pixel_differences"):
        sdk.pixel_differences(bad)
