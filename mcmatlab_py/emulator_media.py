"""The emulator of two estimated media: a grid of one-medium tables (issue #19, both layers).

:class:`TwoMediaEmulator` gives the absorbed power as a function of four optical
coefficients: ``mua``, ``mus`` of the first estimated medium (e.g. the dermis) and
``mua2``, ``mus2`` of a second one (e.g. the epidermis). It holds one
:class:`~mcmatlab_py.emulator.AbsorptionEmulator` (a table over the first medium's
``mua`` x ``mus``) per node of a small log-spaced grid over the second medium's
``mua2`` x ``mus2`` (``n_nodes`` x ``n_nodes``), each built with the second
medium fixed at its node's values: the same cache, checksums, white or direct builds and
on-demand fill as one medium, a table per node. Between the nodes, ``log(NA + offset)``
is interpolated by Lagrange polynomials in ``log mua2`` and ``log mus2`` over all nodes
(degree ``n_nodes - 1``).

Why a grid of tables: the paths depend on every medium's ``mus``, so one white run per
first-medium ``mus`` gives every first-medium ``mua`` for *fixed* second-medium optics;
a thin layer (80 micrometres of epidermis: optical thickness 0.04 in absorption, 0.24 in
reduced scattering) changes the loads smoothly, so a few nodes suffice
(``validation/layered.py --both``, which measures the interpolation against direct Monte
Carlo at off-node points). All node tables share the spec's seed: their Monte Carlo noise
is correlated, and differences between nodes (what the filter learns ``mua2``, ``mus2``
from) are smoother than the noise of one table.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .emulator import AbsorptionEmulator, EmulatorSpec, check_range

__all__ = ["TwoMediaEmulator", "lagrange_weights", "node_specs"]


def node_specs(spec: EmulatorSpec, second: int, mua2: np.ndarray, mus2: np.ndarray) -> list:
    """The one-medium specs of the nodes, ``mua2`` (a,) x ``mus2`` (b,) cm^-1 in C order:
    ``spec`` with medium ``second``'s ``mua`` and ``mus`` set to each node's values."""
    if spec.media is None:
        raise ValueError("a second estimated medium needs a spec of several media "
                         "(EmulatorSpec.from_model(model, medium=...) of a model with regions)")
    if not 0 <= second < len(spec.media) or second == spec.estimated:
        raise ValueError(f"the second medium must be an index of spec.media other than the "
                         f"first estimated one ({spec.estimated}), got {second!r}")
    if not np.any(spec.medium_map == second):
        raise ValueError(f"medium {second} fills no voxel of the spec's medium_map")
    out = []
    for a in mua2:
        for b in mus2:
            media = list(spec.media)
            media[second] = (float(a), float(b), *media[second][2:])
            out.append(dataclasses.replace(spec, media=tuple(media), medium_map=spec.medium_map))
    return out


def lagrange_weights(x: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(N, n) weights of the Lagrange polynomial through ``nodes`` (n,) at ``x`` (N,):
    ``f(x) ~ weights @ f(nodes)``, exact for polynomials of degree n - 1."""
    x = np.asarray(x, float)[:, None]
    n = nodes.size
    w = np.ones((x.shape[0], n))
    for j in range(n):
        for k in range(n):
            if k != j:
                w[:, j] *= (x[:, 0] - nodes[k]) / (nodes[j] - nodes[k])
    return w


@dataclass
class TwoMediaEmulator:
    """NA (or nodal loads) as a function of ``(mua, mus, mua2, mus2)`` cm^-1.

    Build with :meth:`build`. ``unique(mua, mus, mua2, mus2)`` and ``__call__`` take (N,)
    arrays, as :class:`~mcmatlab_py.emulator.AbsorptionEmulator` does for two. Values of
    ``mua2``, ``mus2`` outside the nodes' range are clamped (a ``RuntimeWarning`` that says
    "clamped", which the filter counts) or refused (``out_of_range="error"``).
    """

    tables: list  #: (n_nodes**2,) AbsorptionEmulator, C order over (mua2, mus2)
    second: int  #: index of the second estimated medium in spec.media
    mua2_nodes: np.ndarray  #: (n,) cm^-1
    mus2_nodes: np.ndarray  #: (n,) cm^-1
    out_of_range: str = "error"
    exact = False
    n_media_estimated = 2  #: the filter passes (mua, mus, mua2, mus2)
    _lmua2: np.ndarray = field(init=False, repr=False)
    _lmus2: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.mua2_nodes = np.asarray(self.mua2_nodes, float)
        self.mus2_nodes = np.asarray(self.mus2_nodes, float)
        self._lmua2, self._lmus2 = np.log(self.mua2_nodes), np.log(self.mus2_nodes)
        if len(self.tables) != self.mua2_nodes.size * self.mus2_nodes.size:
            raise ValueError(f"{len(self.tables)} tables for {self.mua2_nodes.size} x "
                             f"{self.mus2_nodes.size} nodes")

    # the one-medium interface, from the first node (all nodes share grid and orbits)
    @property
    def spec(self) -> EmulatorSpec:
        return self.tables[0].spec

    @property
    def shape(self):
        return self.tables[0].shape

    @property
    def kind(self) -> str:
        return self.tables[0].kind

    @property
    def inverse(self) -> np.ndarray:
        return self.tables[0].inverse

    @property
    def have(self) -> np.ndarray:
        """(n_nodes**2, n_mua, n_mus) bool: the table points built so far, per node."""
        return np.stack([t.have for t in self.tables])

    @property
    def complete(self) -> bool:
        return all(t.complete for t in self.tables)

    @property
    def build_seconds(self) -> float:
        return float(sum(t.build_seconds for t in self.tables))

    @property
    def ranges(self) -> dict:
        """``{"mua": .., "mus": .., "mua2": .., "mus2": ..}`` (lo, hi) cm^-1 covered."""
        return {"mua": self.spec.mua_range, "mus": self.spec.mus_range,
                "mua2": (float(self.mua2_nodes[0]), float(self.mua2_nodes[-1])),
                "mus2": (float(self.mus2_nodes[0]), float(self.mus2_nodes[-1]))}

    @classmethod
    def build(cls, spec: EmulatorSpec, second: int, mua2_range, mus2_range, *,
              n_nodes: int = 4, **build_kw) -> TwoMediaEmulator:
        """One :meth:`AbsorptionEmulator.build` of ``spec`` per node of ``n_nodes``
        log-spaced values over ``mua2_range`` x ``mus2_range`` (cm^-1) of medium
        ``second`` (``build_kw``: ``cache_dir``, ``method``, ``on_demand``, ...)."""
        n_nodes = int(n_nodes)
        if n_nodes < 2:
            raise ValueError(f"n_nodes must be >= 2, got {n_nodes}")
        for name, rng in (("mua2_range", mua2_range), ("mus2_range", mus2_range)):
            lo, hi = (float(v) for v in rng)
            if not (np.isfinite(hi) and 0 < lo < hi):
                raise ValueError(f"{name} must be (lo, hi) with 0 < lo < hi (cm^-1), got "
                                 f"{rng!r}")
        mua2, mus2 = np.geomspace(*mua2_range, n_nodes), np.geomspace(*mus2_range, n_nodes)
        out_of_range = build_kw.get("out_of_range", "error")
        tables = [AbsorptionEmulator.build(s, **build_kw)
                  for s in node_specs(spec, second, mua2, mus2)]
        return cls(tables=tables, second=int(second), mua2_nodes=mua2, mus2_nodes=mus2,
                   out_of_range=out_of_range)

    def weights(self, mua2, mus2) -> np.ndarray:
        """(N, n_nodes**2) interpolation weights of the node tables (C order)."""
        mua2 = check_range("mua2", mua2, *self.ranges["mua2"], self.out_of_range,
                           "the emulator's nodes")
        mus2 = check_range("mus2", mus2, *self.ranges["mus2"], self.out_of_range,
                           "the emulator's nodes")
        wa = lagrange_weights(np.log(mua2), self._lmua2)
        wb = lagrange_weights(np.log(mus2), self._lmus2)
        return (wa[:, :, None] * wb[:, None, :]).reshape(wa.shape[0], -1)

    def unique(self, mua, mus, mua2, mus2) -> np.ndarray:
        """(N, n_unique) values at the orbit representatives (see
        :meth:`AbsorptionEmulator.unique`)."""
        W = self.weights(mua2, mus2)
        off = self.spec.offset
        acc = None
        for k, table in enumerate(self.tables):
            term = W[:, k:k + 1] * np.log(table.unique(mua, mus) + off)
            acc = term if acc is None else acc + term
        return np.exp(acc) - off

    def __call__(self, mua, mus, mua2, mus2) -> np.ndarray:
        vals = self.unique(mua, mus, mua2, mus2)
        return vals[:, self.inverse].reshape((vals.shape[0], *self.shape))

    # on demand: the same calls as one table, applied to every node's table
    def needed_box(self, mua_range, mus_range) -> list:
        """Per node, the table points that interpolations in the box read."""
        return [t.needed_box(mua_range, mus_range) for t in self.tables]

    def fill(self, points: list) -> None:
        """Build the points of :meth:`needed_box` in every node's table."""
        for t, p in zip(self.tables, points, strict=True):
            t.fill(p)
