"""Emulators over more inputs than one medium's optics: a grid of one-medium tables.

:class:`NodeGridEmulator` holds one one-medium table per node of a small grid over extra
inputs. Two kinds: the optics of a second estimated medium (:class:`TwoMediaEmulator`,
issue #19, both layers) and the beam's radius (:class:`BeamRadiusEmulator`, issue #18: a
nuisance input the ensemble carries).

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

from .absorption import AbsorptionEmulator, check_range
from .spec import EmulatorSpec

__all__ = ["BeamRadiusEmulator", "NodeGridEmulator", "TwoMediaEmulator", "lagrange_weights",
           "node_specs"]


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
class NodeGridEmulator:
    """NA (or nodal loads) as a function of ``(mua, mus, *extra)``: one
    :class:`~mcmatlab_py.emulator.AbsorptionEmulator` (a table over ``mua`` x ``mus``) per
    node of a small grid over the extra inputs, ``log(NA + offset)`` interpolated between
    the nodes by Lagrange polynomials (in the log of each extra input).

    ``unique(mua, mus, *extra)`` and ``__call__`` take (N,) arrays, as
    :class:`~mcmatlab_py.emulator.AbsorptionEmulator` does for two. Extra inputs outside the
    nodes' range are clamped (a ``RuntimeWarning`` that says "clamped", which the filter
    counts) or refused (``out_of_range="error"``). Subclasses name the inputs:
    :class:`TwoMediaEmulator` (``mua2``, ``mus2``), :class:`BeamRadiusEmulator`
    (``beam_radius``).
    """

    tables: list  #: AbsorptionEmulator per node, C order over the extra inputs
    nodes: dict  #: {name: (n,) node values} of each extra input, in the call's order
    out_of_range: str = "error"
    exact = False
    units = {"mua2": "cm^-1", "mus2": "cm^-1", "beam_radius": "cm"}  #: of the extra inputs
    _lnodes: list = field(init=False, repr=False)

    def __post_init__(self):
        self.nodes = {k: np.asarray(v, float) for k, v in self.nodes.items()}
        self._lnodes = [np.log(v) for v in self.nodes.values()]
        n = int(np.prod([v.size for v in self.nodes.values()]))
        if len(self.tables) != n:
            sizes = " x ".join(str(v.size) for v in self.nodes.values())
            raise ValueError(f"{len(self.tables)} tables for {sizes} nodes")

    @property
    def extra_names(self) -> tuple:
        """The inputs the filter passes after ``mua``, ``mus``."""
        return tuple(self.nodes)

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
        """(n_tables, n_mua, n_mus) bool: the table points built so far, per node."""
        return np.stack([t.have for t in self.tables])

    @property
    def complete(self) -> bool:
        return all(t.complete for t in self.tables)

    @property
    def build_seconds(self) -> float:
        return float(sum(t.build_seconds for t in self.tables))

    @property
    def ranges(self) -> dict:
        """``{"mua": .., "mus": .., name: ..}`` (lo, hi) covered, in each input's units."""
        out = {"mua": self.spec.mua_range, "mus": self.spec.mus_range}
        out.update({k: (float(v[0]), float(v[-1])) for k, v in self.nodes.items()})
        return out

    def weights(self, *extra) -> np.ndarray:
        """(N, n_tables) interpolation weights of the node tables (C order)."""
        W = None
        for (name, nodes), lnodes, x in zip(self.nodes.items(), self._lnodes, extra, strict=True):
            x = check_range(name, x, float(nodes[0]), float(nodes[-1]), self.out_of_range,
                            "the emulator's nodes", self.units.get(name, ""))
            w = lagrange_weights(np.log(x), lnodes)
            W = w if W is None else (W[:, :, None] * w[:, None, :]).reshape(w.shape[0], -1)
        return W

    def unique(self, mua, mus, *extra) -> np.ndarray:
        """(N, n_unique) values at the orbit representatives (see
        :meth:`AbsorptionEmulator.unique`)."""
        W = self.weights(*extra)
        off = self.spec.offset
        acc = None
        for k, table in enumerate(self.tables):
            if not W[:, k].any():  # a node no member reads (e.g. all at a node's value)
                continue
            term = W[:, k:k + 1] * np.log(table.unique(mua, mus) + off)
            acc = term if acc is None else acc + term
        return np.exp(acc) - off

    def __call__(self, mua, mus, *extra) -> np.ndarray:
        vals = self.unique(mua, mus, *extra)
        return vals[:, self.inverse].reshape((vals.shape[0], *self.shape))

    # on demand: the same calls as one table, applied to every node's table
    def needed_box(self, mua_range, mus_range) -> list:
        """Per node, the table points that interpolations in the box read."""
        return [t.needed_box(mua_range, mus_range) for t in self.tables]

    def fill(self, points: list) -> None:
        """Build the points of :meth:`needed_box` in every node's table."""
        for t, p in zip(self.tables, points, strict=True):
            t.fill(p)


def _check_node_range(name: str, rng, unit: str) -> tuple[float, float]:
    lo, hi = (float(v) for v in rng)
    if not (np.isfinite(hi) and 0 < lo < hi):
        raise ValueError(f"{name} must be (lo, hi) with 0 < lo < hi ({unit}), got {rng!r}")
    return lo, hi


def _check_n_nodes(n_nodes, least: int = 2) -> int:
    n_nodes = int(n_nodes)
    if n_nodes < least:
        raise ValueError(f"n_nodes must be >= {least}, got {n_nodes}")
    return n_nodes


class TwoMediaEmulator(NodeGridEmulator):
    """NA (or nodal loads) as a function of ``(mua, mus, mua2, mus2)`` cm^-1: a node grid
    over the second estimated medium's optics (``n_nodes`` x ``n_nodes``)."""

    n_media_estimated = 2  #: the filter passes (mua, mus, mua2, mus2)

    def __init__(self, tables, second: int, mua2_nodes, mus2_nodes, out_of_range="error"):
        self.second = int(second)  #: index of the second estimated medium in spec.media
        super().__init__(tables=tables, nodes={"mua2": mua2_nodes, "mus2": mus2_nodes},
                         out_of_range=out_of_range)

    @property
    def mua2_nodes(self) -> np.ndarray:
        return self.nodes["mua2"]

    @property
    def mus2_nodes(self) -> np.ndarray:
        return self.nodes["mus2"]

    @classmethod
    def build(cls, spec: EmulatorSpec, second: int, mua2_range, mus2_range, *,
              n_nodes: int = 4, **build_kw) -> TwoMediaEmulator:
        """One :meth:`AbsorptionEmulator.build` of ``spec`` per node of ``n_nodes``
        log-spaced values over ``mua2_range`` x ``mus2_range`` (cm^-1) of medium
        ``second`` (``build_kw``: ``cache_dir``, ``method``, ``on_demand``, ...)."""
        n_nodes = _check_n_nodes(n_nodes)
        mua2 = np.geomspace(*_check_node_range("mua2_range", mua2_range, "cm^-1"), n_nodes)
        mus2 = np.geomspace(*_check_node_range("mus2_range", mus2_range, "cm^-1"), n_nodes)
        out_of_range = build_kw.get("out_of_range", "error")
        tables = [AbsorptionEmulator.build(s, **build_kw)
                  for s in node_specs(spec, second, mua2, mus2)]
        return cls(tables, second, mua2, mus2, out_of_range=out_of_range)


class BeamRadiusEmulator(NodeGridEmulator):
    """NA (or nodal loads) as a function of ``(mua, mus, beam_radius)`` (cm^-1, cm): a
    node per beam radius, for a beam whose radius is known only to some percent (the
    filter then carries it as an uncertain input, ``estimate = ["mua", "mus",
    "beam_radius"]``; ``docs/enkf.md``).

    Each node is the spec with ``radius`` set to the node's value: the same photons, seed,
    cache and on-demand fill as one table. ``log(NA + offset)`` is interpolated by a
    Lagrange polynomial in ``log radius`` through all nodes (``validation/beam_radius.py``
    measures it against direct Monte Carlo between the nodes).
    """

    n_media_estimated = 1

    def __init__(self, tables, radius_nodes, out_of_range="error"):
        super().__init__(tables=tables, nodes={"beam_radius": radius_nodes},
                         out_of_range=out_of_range)

    @property
    def radius_nodes(self) -> np.ndarray:
        """(n,) cm."""
        return self.nodes["beam_radius"]

    @classmethod
    def build(cls, spec: EmulatorSpec, radius_range, *, n_nodes: int = 4,
              **build_kw) -> BeamRadiusEmulator:
        """One :meth:`AbsorptionEmulator.build` of ``spec`` per node of ``n_nodes``
        log-spaced radii over ``radius_range`` (cm) (``build_kw``: ``cache_dir``,
        ``method``, ``on_demand``, ...)."""
        n_nodes = _check_n_nodes(n_nodes)
        if spec.source_type not in ("tophat", "gaussian"):
            raise ValueError(f"the beam radius is an input of a 'tophat' or 'gaussian' beam, "
                             f"not of spec.source_type = {spec.source_type!r}")
        radii = np.geomspace(*_check_node_range("radius_range", radius_range, "cm"), n_nodes)
        out_of_range = build_kw.get("out_of_range", "error")
        tables = [AbsorptionEmulator.build(dataclasses.replace(spec, radius=float(r),
                                                               medium_map=spec.medium_map),
                                           **build_kw) for r in radii]
        return cls(tables, radii, out_of_range=out_of_range)
