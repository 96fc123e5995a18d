"""Smooth primitives: stated error bounds and slopes."""

import numpy as np
import pytest

from hystmpc.models.smooth import smooth_abs, smooth_clip, smooth_max, smooth_min

X = np.linspace(-5, 5, 20001)


@pytest.mark.parametrize("eps", [1e-1, 1e-2, 1e-4])
def test_bounds(eps):
    err_clip = smooth_clip(X, 1.3, eps) - np.clip(X, -1.3, 1.3)
    assert np.max(np.abs(err_clip)) <= eps / 2 + 1e-15
    assert np.max(np.abs(err_clip)) >= 0.4 * eps  # the bound is tight, not loose
    err_max = smooth_max(X, 0.7, eps) - np.maximum(X, 0.7)
    assert 0 <= err_max.min() and err_max.max() <= eps / 2 + 1e-15
    err_min = smooth_min(X, 0.7, eps) - np.minimum(X, 0.7)
    assert -eps / 2 - 1e-15 <= err_min.min() and err_min.max() <= 0
    err_abs = np.abs(X) - smooth_abs(X, eps)
    assert 0 <= err_abs.min() and err_abs.max() <= eps + 1e-15


def test_smooth_clip_is_monotone_and_odd():
    y = smooth_clip(X, 1.0, 1e-2)
    assert np.all(np.diff(y) >= 0)
    np.testing.assert_allclose(y, -smooth_clip(-X, 1.0, 1e-2), atol=1e-15)
