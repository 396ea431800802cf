"""Symmetric sparse operators on at most three diagonals above the main one: the 7-point
pattern of a structured box mesh, applied from its diagonals.

The P1 stiffness of the Kuhn mesh (:func:`fem.box_mesh`) couples only neighbours along the
axes, and lumped masses and convective faces add to the diagonal alone. Read from three rows
of couplings, a product streams 5 numbers a node and no column indices, where CSR's streams
7 values and 7 indices (the explicit stages of :mod:`mcmatlab_py.heat.rkc`)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import _kernels
from ._kernels import banded_at

__all__ = ["banded_at", "banded_operator"]


def banded_operator(A):
    """``(diag, off, strides)`` of a symmetric sparse ``A`` whose entries lie on at most
    three diagonals above the main one (and their mirror images), or None.

    The P1 stiffness of a structured Kuhn mesh couples only neighbours along the axes
    (:func:`fem.box_mesh`): the 7-point pattern, diagonals 1, nz + 1 and (ny + 1)(nz + 1)
    away. Applied from three (n,) rows of couplings instead of CSR's column indices, a
    product reads 5 numbers a node instead of 13, and no scattered indices.
    """
    A = sp.csr_array(A)
    A.sum_duplicates()
    n = A.shape[0]
    diag, off, strides = np.zeros(n), np.zeros((3, n)), np.zeros(3, np.int64)
    if not _kernels.banded_from_csr(A.indptr, A.indices, np.asarray(A.data, np.float64),
                                    diag, off, strides):
        return None
    order = np.argsort(strides, kind="stable")
    return diag, np.ascontiguousarray(off[order]), strides[order]

