"""An independent 1-D slab Monte Carlo: the reference for MCmatlab Example 20.

Example 20 (ReflectanceStatisticsAndCyclicBoundaries) is, with its cyclic sides, a
laterally infinite slab: one voxel layer (0.1 cm) of air (mua = 1e-8, mus = 100 cm^-1,
g = 1: no change of direction, no absorption worth counting) over 1.9 cm of standard
tissue (mua = 1, mus = 100 cm^-1, g = 0.9, n = 1.4), a pencil beam at normal incidence.
Matched interfaces: no Fresnel anywhere. Mismatched: Fresnel reflection and refraction
between tissue and air at the top; the cuboid's bottom face lets light out as MCmatlab's
faces do (no Fresnel; the transmittance is 2e-5 of the power anyway). Issue #46 left a
0.27% difference open there (ours absorbs 0.5992 +- 0.0003 and 0.7205, MCmatlab
0.5976 +- 0.0007 and 0.7186); this script says which is right.

The Monte Carlo shares nothing with ``mcmatlab_py``: no voxels, no fixed-point weights,
numpy's Generator for its random numbers. Only the direction cosine uz and the depth z
of a packet matter in a laterally uniform slab. Analog packets (absorbed whole with
probability mua / (mua + mus) at an interaction, so every tally is a binomial count),
Henyey-Greenstein scattering, Fresnel (unpolarised) reflection decided packet by
packet; the beam's specular part at entry, ((n - 1) / (n + 1))^2, is exact, the
remaining packets start just inside. Step lengths are memoryless, so a packet reflected
at a face starts a fresh step there. Standard errors come from independent batches.

Checked first against MCML's manual Table 6.1 (van de Hulst 1980): slab n = 1,
mua = 10, mus = 90 cm^-1, g = 0.75, d = 0.02 cm: diffuse reflectance 0.09739, total
transmittance 0.66096.

    nice python validation/slab_reference.py [--photons 40000000] [--batches 20] [--ours 20000000]

(about 1 minute per 10^7 packets of Example 20 on one core; ``--ours``: our engine, for
comparison, on the issue's 21 x 21 x 20 grid, 2 minutes per 10^7 packets). Writes
validation/reports/slab_reference.md.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numba
import numpy as np

__all__ = ["slab_mc", "fresnel"]


# no cache=True: a cache written when imported as validation.slab_reference fails when
# run as a script, and the other way round; compiling takes a second
@numba.njit
def fresnel(n1, n2, cos_i):
    """Unpolarised Fresnel reflectance from medium n1 into n2 at incidence cosine cos_i."""
    if n1 == n2:
        return 0.0
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
    if sin_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t * sin_t)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return 0.5 * (rs * rs + rp * rp)


@numba.njit
def _run(n_photons, mua, mus, g, d, n_slab, n_top, n_bottom, rng):
    """Counts of packets (reflected, absorbed, transmitted) that entered the slab."""
    mut = mua + mus
    p_absorb = mua / mut
    n_r = 0
    n_a = 0
    n_t = 0
    for _ in range(n_photons):
        z = 0.0
        uz = 1.0
        while True:
            s = -math.log(1.0 - rng.random()) / mut
            if uz < 0.0 and z + s * uz <= 0.0:  # reaches the top face
                z = 0.0
                if rng.random() < fresnel(n_slab, n_top, -uz):
                    uz = -uz
                    continue
                n_r += 1
                break
            if uz > 0.0 and z + s * uz >= d:  # reaches the bottom face
                z = d
                if rng.random() < fresnel(n_slab, n_bottom, uz):
                    uz = -uz
                    continue
                n_t += 1
                break
            z += s * uz
            if rng.random() < p_absorb:
                n_a += 1
                break
            # Henyey-Greenstein deflection; only the new z cosine is needed
            if g == 0.0:
                ct = 2.0 * rng.random() - 1.0
            else:
                f = (1.0 - g * g) / (1.0 - g + 2.0 * g * rng.random())
                ct = (1.0 + g * g - f * f) / (2.0 * g)
            ct = min(1.0, max(-1.0, ct))
            st = math.sqrt(1.0 - ct * ct)
            cphi = math.cos(2.0 * math.pi * rng.random())
            uz = uz * ct + math.sqrt(max(0.0, 1.0 - uz * uz)) * st * cphi
    return n_r, n_a, n_t


def slab_mc(n_photons: int, mua: float, mus: float, g: float, d: float, n_slab: float = 1.0,
            n_top: float = 1.0, n_bottom: float | None = None, batches: int = 20,
            seed: int = 0) -> dict:
    """Total reflectance, absorptance and transmittance of a slab lit at normal incidence.

    Parameters
    ----------
    n_photons : packets in all, split into ``batches`` independent batches.
    mua, mus : absorption and scattering coefficients, cm^-1.
    g : Henyey-Greenstein anisotropy.
    d : thickness, cm.
    n_slab, n_top, n_bottom : refractive indices of the slab and of the media above and
        below (``n_bottom = None``: as the slab, a face without Fresnel).

    Returns
    -------
    dict with ``R`` (total, the specular part included), ``A``, ``T``, each a
    (mean, standard error) pair over the batches, and ``specular``.
    """
    n_bottom = n_slab if n_bottom is None else n_bottom
    r0 = float(fresnel(n_top, n_slab, 1.0))  # the beam's specular part, exact
    per = n_photons // batches
    rows = []
    for b in range(batches):
        rng = np.random.default_rng([seed, b])
        counts = _run(per, float(mua), float(mus), float(g), float(d), float(n_slab),
                      float(n_top), float(n_bottom), rng)
        rows.append(np.array(counts, dtype=float) / per * (1.0 - r0))
    rows = np.array(rows)
    rows[:, 0] += r0
    mean = rows.mean(0)
    se = rows.std(0, ddof=1) / math.sqrt(batches)
    return {"R": (mean[0], se[0]), "A": (mean[1], se[1]), "T": (mean[2], se[2]),
            "specular": r0, "n_photons": per * batches}


#: Issue #46's pooled numbers for Example 20: (ours, its SE, MCmatlab, its SE), absorbed.
EX20_AGREEMENT = {"matched": (0.5992, 0.0003, 0.5976, 0.0007),
                  "mismatched": (0.7205, 0.0003, 0.7186, 0.0007)}


def ours_ex20(n_photons: int, matched: bool, runs: int = 20) -> tuple[float, float]:
    """Our engine on the comparison's grid (21 x 21 x 20): absorbed fraction, mean and
    standard error over ``runs`` runs of ``n_photons / runs`` packets."""
    import sys
    sys.path.insert(0, str(Path(__file__).parents[1] / "examples" / "mcmatlab"))
    from ex20_reflectance_statistics import build

    A = []
    for k in range(runs):
        model = build(False)
        model.G.nx, model.G.ny, model.G.nz = 21, 21, 20
        model.MC.n_photons_requested = n_photons // runs
        model.MC.matched_interfaces = matched
        model.MC.seed = 777_000 + k + (0 if matched else 1000)
        A.append(model.run_monte_carlo().MC.absorbed_fraction)
    return float(np.mean(A)), float(np.std(A, ddof=1) / math.sqrt(runs))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=40_000_000, help="per Example 20 case")
    ap.add_argument("--check-photons", type=int, default=10_000_000, help="for the MCML case")
    ap.add_argument("--batches", type=int, default=20)
    ap.add_argument("--ours", type=int, default=0,
                    help="packets per case of our engine on the comparison's grid (0: none)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "reports" / "slab_reference.md"))
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    chk = slab_mc(args.check_photons, 10.0, 90.0, 0.75, 0.02, batches=args.batches, seed=1)
    lines = ["# Example 20 against an independent slab Monte Carlo", "",
             f"Command: `python validation/slab_reference.py --photons {args.photons} "
             f"--check-photons {args.check_photons} --batches {args.batches}"
             + (f" --ours {args.ours}`" if args.ours else "`"), "",
             "Standard errors from the scatter of independent batches.", "",
             f"## Check: MCML Table 6.1 (van de Hulst 1980), {chk['n_photons']:.3g} packets", "",
             "| quantity | this Monte Carlo | SE | published | z |", "|---|---:|---:|---:|---:|"]
    for name, key, ref in (("diffuse reflectance", "R", 0.09739),
                           ("total transmittance", "T", 0.66096)):
        m, se = chk[key]
        lines.append(f"| {name} | {m:.5f} | {se:.5f} | {ref} | {(m - ref) / se:+.2f} |")
    lines += ["", "## Example 20: 1.9 cm of tissue (mua = 1, mus = 100 cm^-1, g = 0.9) under "
              "air, normal incidence", "",
              "| case | R (total) | A | T | ours: A | z | MCmatlab: A | z |",
              "|---|---:|---:|---:|---:|---:|---:|---:|"]
    rerun = ["", "### Our engine rerun with more packets (21 x 21 x 20 voxels, 20 runs)", "",
             "| case | packets | ours: A | z |", "|---|---:|---:|---:|"]
    for k, (name, n_slab) in enumerate((("matched", 1.0), ("mismatched", 1.4))):
        res = slab_mc(args.photons, 1.0, 100.0, 0.9, 1.9, n_slab=n_slab, n_top=1.0,
                      batches=args.batches, seed=10 + k)
        (R, sR), (A, sA), (T, sT) = res["R"], res["A"], res["T"]
        ours, s_ours, mcm, s_mcm = EX20_AGREEMENT[name]
        z_ours = (ours - A) / math.hypot(s_ours, sA)
        z_mcm = (mcm - A) / math.hypot(s_mcm, sA)
        lines.append(f"| {name} ({res['n_photons']:.3g} packets) | {R:.5f} +- {sR:.5f} | "
                     f"{A:.5f} +- {sA:.5f} | {T:.2e} +- {sT:.1e} | {ours} +- {s_ours} | "
                     f"{z_ours:+.1f} | {mcm} +- {s_mcm} | {z_mcm:+.1f} |")
        print(lines[-1], flush=True)
        if args.ours:
            m, se = ours_ex20(args.ours, name == "matched")
            rerun.append(f"| {name} | {args.ours:.3g} | {m:.5f} +- {se:.5f} | "
                         f"{(m - A) / math.hypot(se, sA):+.1f} |")
    if args.ours:
        lines += rerun
    lines += ["", "z: (engine - reference) / the two standard errors combined. "
              f"Run time {time.perf_counter() - t0:.0f} s.", ""]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
