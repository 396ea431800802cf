"""Independent check of the FEM heat core against a cell-centred finite-difference solver.

The reference is the scheme of MCmatlab's heat solver: one unknown per voxel
centre, 7-point fluxes with harmonic-mean conductances between voxels,
insulating or convective faces, implicit (theta) time stepping.  It shares no
code with :mod:`fem`.  Both discretize the same continuous problem (a
voxel-wise constant source, insulating sides and bottom, a convective top),
so their voxel averages must approach each other at second order as the
grids refine.

Run ``python validation/fem_fd_reference.py`` to write
``validation/reports/fem_fd_reference.md``; ``tests/test_fem_convergence.py``
runs a small version.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def fd_heat(shape, lengths, S, vhc, tc, dt, n_steps, T0, theta=1.0, h_top=0.0, T_amb=0.0):
    """Cell-centred FD heat solver on a voxel grid.

    Parameters
    ----------
    shape : (nx, ny, nz)
    lengths : (Lx, Ly, Lz), cm
    S : array (nx, ny, nz), W/cm^3
    vhc, tc : float or array (nx, ny, nz)
        J cm^-3 K^-1 and W cm^-1 K^-1 per voxel.
    dt : float, s
    n_steps : int
    T0 : float or array (nx, ny, nz), deg C
    theta : float
    h_top : float
        W cm^-2 K^-1 on the top face z = 0 (0: insulating); other faces insulating.
    T_amb : float, deg C

    Returns
    -------
    array (nx, ny, nz), voxel temperatures after ``n_steps``.
    """
    nx, ny, nz = shape
    d = np.array(lengths, float) / np.array(shape)
    V = d.prod()
    n = nx * ny * nz
    c = np.broadcast_to(np.asarray(vhc, float), shape).ravel()
    k = np.broadcast_to(np.asarray(tc, float), shape)
    idx = np.arange(n).reshape(shape)
    rows, cols, vals = [], [], []
    for axis in range(3):
        area = V / d[axis]
        sl0 = [slice(None)] * 3
        sl1 = [slice(None)] * 3
        sl0[axis] = slice(0, -1)
        sl1[axis] = slice(1, None)
        k0, k1 = k[tuple(sl0)], k[tuple(sl1)]
        G = (area / (d[axis] / (2 * k0) + d[axis] / (2 * k1))).ravel()
        i0, i1 = idx[tuple(sl0)].ravel(), idx[tuple(sl1)].ravel()
        rows += [i0, i1, i0, i1]
        cols += [i0, i1, i1, i0]
        vals += [G, G, -G, -G]
    Kfd = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                        shape=(n, n))
    g = np.zeros(n)
    if h_top > 0:
        top = idx[:, :, 0].ravel()
        Gt = d[0] * d[1] / (d[2] / (2 * k[:, :, 0].ravel()) + 1.0 / h_top)
        Kfd = Kfd + sp.csr_matrix((Gt, (top, top)), shape=(n, n))
        g[top] = Gt * T_amb
    C = sp.diags_array(c * V)
    A = (C / dt + theta * Kfd).tocsc()
    B = (C / dt - (1 - theta) * Kfd).tocsr()
    lu = spla.splu(A)
    q = np.asarray(S, float).ravel() * V + g
    T = np.broadcast_to(np.asarray(T0, float), shape).ravel().copy()
    for _ in range(n_steps):
        T = lu.solve(B @ T + q)
    return T.reshape(shape)


def beam_source(shape, lengths, S0=100.0, w=0.1, mua=10.0):
    """Voxel-centre samples of a Gaussian beam absorbed with depth, W/cm^3."""
    nx, ny, nz = shape
    Lx, Ly, Lz = lengths
    x = (np.arange(nx) + 0.5) * Lx / nx - Lx / 2
    y = (np.arange(ny) + 0.5) * Ly / ny - Ly / 2
    z = (np.arange(nz) + 0.5) * Lz / nz
    r2 = x[:, None, None] ** 2 + y[None, :, None] ** 2
    return S0 * np.exp(-2 * r2 / w**2) * np.exp(-mua * z[None, None, :])


def fem_vs_fd(levels, base=(4, 4, 2), lengths=(0.5, 0.5, 0.25), t_end=0.5, n_steps=20,
              theta=0.5, vhc=3.9, tc=0.0052, h_top=0.005, T_amb=20.0, T0=37.0):
    """RMS difference of coarse-voxel averages of FEM and FD, per refinement level.

    The source is sampled at the voxel centres of the coarsest grid (so it is
    the same function on every level) and both solutions are averaged over
    the coarsest voxels.  ``theta=1, n_steps=1, t_end=1e9`` gives the steady
    state (no time error).  Returns a list of (h, rms difference, fem seconds).
    """
    from fem import BoxGrid, FaceBC, HeatBoundary, HeatStepper, voxel_load_matrix

    coarse = BoxGrid(*base, *lengths)
    S_c = beam_source(coarse.shape, lengths)
    out = []
    for r in levels:
        g = BoxGrid(*(r * np.array(base)), *lengths)
        S = np.repeat(np.repeat(np.repeat(S_c, r, 0), r, 1), r, 2)
        dt = t_end / n_steps
        T_fd = fd_heat(g.shape, lengths, S, vhc, tc, dt, n_steps, T0, theta=theta,
                       h_top=h_top, T_amb=T_amb)
        fd_avg = T_fd.reshape(base[0], r, base[1], r, base[2], r).mean(axis=(1, 3, 5))
        mesh = g.mesh()
        bc = HeatBoundary({"z-": FaceBC("convective", temperature=T_amb, h=h_top)})
        t0 = time.perf_counter()
        stepper = HeatStepper(mesh, vhc, tc, dt, theta=theta, boundary=bc)
        load = voxel_load_matrix(mesh, g) @ S.ravel()
        T = stepper.run(np.full(mesh.p.shape[1], T0), n_steps, load)
        secs = time.perf_counter() - t0
        Lc = voxel_load_matrix(mesh, coarse)  # exact integrals over coarse voxels
        fem_avg = (Lc.T @ T).reshape(coarse.shape) / (coarse.dx * coarse.dy * coarse.dz)
        out.append((g.dx, float(np.sqrt(np.mean((fem_avg - fd_avg) ** 2))), secs))
    return out


def main(out: str | Path | None = None):
    levels = (1, 2, 4, 8)
    cases = [
        ("steady state (one backward-Euler step of 1e9 s)", dict(theta=1.0, n_steps=1, t_end=1e9)),
        ("transient, backward Euler, 400 steps to 0.5 s", dict(theta=1.0, n_steps=400, t_end=0.5)),
    ]
    lines = [
        "# FEM heat core vs cell-centred finite differences",
        "",
        "Generated by `python validation/fem_fd_reference.py`.",
        "",
        "Gaussian-beam source (w = 0.1 cm, mua = 10 /cm, 100 W/cm^3 peak) sampled on a",
        "4x4x2 voxel grid over 0.5 x 0.5 x 0.25 cm, refined by r per axis on both",
        "solvers; convective top (h = 0.005 W cm^-2 K^-1, 20 C), other faces",
        "insulating; 37 C start; VHC 3.9, TC 0.0052.  Metric: RMS difference of the",
        "averages over the 32 coarse voxels (FEM averages are exact integrals of the",
        "P1 field).  Both schemes are second order, so the difference must fall as h^2.",
        "",
    ]
    for title, kw in cases:
        res = fem_vs_fd(levels, **kw)
        h = np.array([r[0] for r in res])
        d = np.array([r[1] for r in res])
        slope = np.polyfit(np.log(h), np.log(d), 1)[0]
        lines += [f"## {title}", "", "| r | h (cm) | RMS(FEM - FD) (K) | FEM time (s) |",
                  "|---|---|---|---|"]
        for r, (hh, dd, s) in zip(levels, res, strict=True):
            lines.append(f"| {r} | {hh:.5f} | {dd:.3e} | {s:.2f} |")
        local = np.log2(d[:-1] / d[1:])
        lines += ["", f"Fitted order (np.polyfit, all levels): **{slope:.2f}**; "
                  f"successive orders: {', '.join(f'{x:.2f}' for x in local)}", ""]
    out = Path(out) if out is not None else Path(__file__).parent / "reports" / "fem_fd_reference.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "fem_fd_reference.md"))
    main(ap.parse_args().out)
