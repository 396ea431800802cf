r"""The ensemble smoother with multiple data assimilation (ES-MDA) for constant parameters.

A filter takes the readings one at a time and moves the parameters by one linear update
per reading. Where the parameters are constant over a window and the model maps them to
the window's readings through a curved relation (the mua-mus ridge of one surface
sensor), these small sequential moves lose some of the information that all readings
together hold (``docs/layered.md``: the filter's mus error 1.9 times the Cramér-Rao
bound, where the least-squares fit of the same data reaches it).

ES-MDA (Emerick & Reynolds 2013, Computers & Geosciences 55, 3-15) updates the parameter
ensemble with *all* the window's readings at once, ``n_iter`` times, each time with the
error covariance multiplied by :math:`\alpha_i` (:math:`\sum_i 1/\alpha_i = 1`) and the
predictions re-run from the updated parameters:

.. math::

    U^{i+1} = U^i + C_{UD}^i\,\big(C_{DD}^i + \alpha_i R\big)^{-1}
              \big(y + \sqrt{\alpha_i}\,\epsilon - G(U^i)\big),

which for a linear ``G`` and Gaussian prior gives the posterior's moments, and for a
nonlinear one takes ``n_iter`` small, nearly linear steps. Each update is one analysis of
:func:`enkf.analysis.analysis` in ensemble space (its cost is linear in the number of
readings): ``method="etkf"`` (default, the project's) the deterministic square root, which
assimilating the same data ``n_iter`` times with the error covariance times
:math:`\alpha_i` also gives the linear posterior's moments (Emerick 2016) without the
sampling noise of the perturbations; ``"enkf"`` the perturbed observations of Emerick &
Reynolds (the term :math:`\sqrt{\alpha_i}\,\epsilon` above). On the layered twins the
two gave the same errors (``docs/layered.md``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .analysis import analysis
from .checks import float_array
from .problem import DEFAULT_METHOD

__all__ = ["es_mda", "mda_alphas"]


def mda_alphas(n_iter: int) -> np.ndarray:
    """``n_iter`` equal inflation factors (each ``n_iter``: their inverses sum to 1)."""
    if not (isinstance(n_iter, (int, np.integer)) and n_iter >= 1):
        raise ValueError(f"n_iter must be an integer >= 1, got {n_iter!r}")
    return np.full(int(n_iter), float(n_iter))


def es_mda(simulate: Callable[[np.ndarray], np.ndarray], U: np.ndarray, y: np.ndarray,
           R: np.ndarray, rng: np.random.Generator, *, n_iter: int = 4,
           alphas: np.ndarray | None = None, method: str = DEFAULT_METHOD,
           center: bool = True,
           callback: Callable[[int, np.ndarray], None] | None = None,
           whiten: Callable[[np.ndarray], Callable[[np.ndarray], np.ndarray]] | None = None
           ) -> np.ndarray:
    """The parameter ensemble after ES-MDA (module doc).

    Parameters
    ----------
    simulate : callable
        ``simulate(U) -> (N, p)``: the predicted readings of the members ``U`` (N, n_par),
        the window's readings flattened; a member's non-finite prediction raises
        FloatingPointError.
    U : (N, n_par) the prior ensemble (in the space the update is linear in, e.g. logs)
    y : (p,) the readings
    R : (p,) or (p, p) their error variances or covariance
    rng : the generator of the perturbations (``"enkf"``)
    n_iter : the number of updates, with equal factors (:func:`mda_alphas`)
    alphas : the factors instead; their inverses must sum to 1
    method : ``"etkf"`` or ``"enkf"`` (module doc); ``center`` for ``"enkf"``
    callback : ``callback(i, U)`` after each update ``i`` (progress)
    whiten : readings whose error depends on the predictions (a relative error, as a
        camera's model error): ``whiten(Y)`` with an update's predictions ``Y`` (N, p)
        returns the map ``w`` that makes readings of unit, independent error at that
        forecast, ``w(Z)`` for (M, p) arrays; each update then analyses ``w(Y)`` against
        ``w(y)`` with error ``R``, which must be 1 (the filter's forecast-dependent
        ``obs_error`` in a smoother)
    """
    U = float_array(U, "U", 2).copy()
    y = float_array(y, "y", 1)
    alphas = mda_alphas(n_iter) if alphas is None else float_array(alphas, "alphas", 1)
    if np.any(alphas <= 0) or not np.isclose(np.sum(1.0 / alphas), 1.0, rtol=1e-9):
        raise ValueError(f"alphas must be > 0 with inverses summing to 1, got {alphas!r}")
    if not np.all(np.isfinite(y)):
        raise ValueError("y must be finite (drop missing readings before the smoother)")
    R = np.asarray(R, float)
    if whiten is not None and not (R.shape == y.shape and np.all(R == 1.0)):
        raise ValueError("with whiten the readings' error R must be 1 (whitened readings)")
    for i, a in enumerate(alphas):
        Y = np.asarray(simulate(U), float)
        if Y.shape != (U.shape[0], y.size):
            raise ValueError(f"simulate must return shape {(U.shape[0], y.size)}, got {Y.shape}")
        if not np.all(np.isfinite(Y)):
            raise FloatingPointError(f"ES-MDA update {i + 1}: a member's predictions are not "
                                     "finite")
        yi = y
        if whiten is not None:
            w = whiten(Y)
            Y, yi = w(Y), w(y[None, :])[0]
        U = analysis(U, Y, yi, a * R, method, rng, center=center)
        if callback is not None:
            callback(i, U)
    return U
