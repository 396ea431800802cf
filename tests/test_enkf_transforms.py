"""Parameter transforms: round trips, positivity, domains."""

import numpy as np
import pytest

from enkf import IdentityTransform, LogitTransform, LogTransform
from enkf.transforms import as_transforms, to_filter_space, to_physical


@pytest.mark.parametrize(
    "tr, theta",
    [
        (IdentityTransform(), np.array([-3.0, 0.0, 2.5, 1e6])),
        (LogTransform(), np.array([1e-8, 0.37, 1.0, 150.0, 1e8])),  # mua, mus in cm^-1
        (LogitTransform(0.5, 2.0), np.array([0.5 + 1e-9, 0.7, 1.0, 1.99999])),
    ],
)
def test_round_trip(tr, theta):
    np.testing.assert_allclose(tr.inverse(tr.forward(theta)), theta, rtol=1e-12)
    u = np.linspace(-5, 5, 11)
    np.testing.assert_allclose(tr.forward(tr.inverse(u)), u, rtol=1e-9, atol=1e-9)


def test_positivity_and_bounds_for_any_filter_value():
    # Whatever the Kalman update does to u, the physical parameter stays admissible.
    u = np.array([-800.0, -50.0, -1.0, 0.0, 1.0, 50.0, 700.0])
    assert np.all(LogTransform().inverse(u) > 0)
    th = LogitTransform(0.5, 2.0).inverse(u)
    assert np.all((th > 0.5) & (th < 2.0))


def test_forward_domain_errors():
    with pytest.raises(ValueError, match="^theta"):
        LogTransform().forward(np.array([1.0, 0.0]))
    with pytest.raises(ValueError, match="^theta"):
        LogitTransform(0.0, 1.0).forward(np.array([0.5, 1.0]))
    with pytest.raises(ValueError, match="^hi"):
        LogitTransform(1.0, 1.0)
    with pytest.raises(ValueError, match="^lo"):
        LogitTransform(-np.inf, 1.0)


def test_columnwise_application():
    trs = as_transforms([LogTransform(), IdentityTransform(), LogitTransform(0, 10)], 3)
    theta = np.array([[2.0, -1.0, 5.0], [0.1, 3.0, 9.0]])
    u = to_filter_space(trs, theta)
    np.testing.assert_allclose(u[:, 0], np.log(theta[:, 0]))
    np.testing.assert_allclose(u[:, 1], theta[:, 1])
    np.testing.assert_allclose(to_physical(trs, u), theta, rtol=1e-12)
    assert as_transforms(LogTransform(), 2) == (LogTransform(), LogTransform())
    with pytest.raises(ValueError, match="^transforms"):
        as_transforms([LogTransform()], 2)
    with pytest.raises(ValueError, match=r"^transforms\[0\]"):
        as_transforms(["log"], 1)
