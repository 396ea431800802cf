"""Files every run writes: the estimates table, and JSON with NumPy values made plain."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

__all__ = ["jsonable", "readable_stop", "write_advice_csv", "write_estimates_csv",
           "write_json"]


def readable_stop(message: str | None, names) -> str | None:
    """The health check's message (``est.diverged``) with parameter indices replaced by
    their ``names``: summary.json's ``stopped``, of ``identify`` and ``paper`` alike."""
    if not message:
        return message
    return re.sub(r"parameter (\d+)",
                  lambda m: f"parameter {names[int(m.group(1))]}"
                  if int(m.group(1)) < len(names) else m.group(0), message)


def write_estimates_csv(path, est, truth=None, data=None) -> None:
    """``estimates.csv``: time; mean and std of each parameter (then, with damage-driven
    optics, of the effective mua and mus and the mean coagulated fraction; with estimated
    sensor offsets, of each offset in deg C) and of each tracked temperature."""
    cols = ["time_s"]
    arrays = [est.times]
    for i, name in enumerate(est.names):
        cols += [f"{name}_mean", f"{name}_std"]
        arrays += [est.param_mean[:, i], est.param_std[:, i]]
    if getattr(est, "effective_mean", None) is not None:  # damage-driven optics
        for i, name in enumerate(("mua", "mus")):
            cols += [f"{name}_eff_mean", f"{name}_eff_std"]
            arrays += [est.effective_mean[:, i], est.effective_std[:, i]]
        cols.append("coagulated_fraction_mean")
        arrays.append(est.coagulated_fraction)
    if getattr(est, "sensor_offset_mean", None) is not None:  # estimated sensor offsets
        for j in range(est.sensor_offset_mean.shape[1]):
            cols += [f"sensor{j + 1}_offset_mean", f"sensor{j + 1}_offset_std"]
            arrays += [est.sensor_offset_mean[:, j], est.sensor_offset_std[:, j]]
    if getattr(est, "drift_weight", None) is not None:  # the bank: how probable a drift is
        cols.append("drift_weight")
        arrays.append(est.drift_weight)
    for j, pos in enumerate(est.tracked_positions):
        tag = f"T_z{pos[2]:.2f}"
        cols += [f"{tag}_mean", f"{tag}_std"]
        arrays += [est.tracked_mean[:, j], est.tracked_std[:, j]]
    if data is not None:
        cols.append("sensor_data")
        arrays.append(np.r_[np.nan, data][: len(est.times)])
    table = np.column_stack(arrays)
    np.savetxt(path, table, delimiter=",", header=",".join(cols), comments="", fmt="%.8g")


def write_advice_csv(out, rows, quantiles, header: bool = True) -> None:
    """``advice.csv`` (:mod:`enkf.tissue.advice`): one line per reading, the columns of
    :meth:`~enkf.tissue.advice.AdviceRow.as_dict` (times in s; ``inf``: the target is not
    reached within the forecast's horizon). ``out``: a path, or an open text file to which
    the lines are added (``header``: the column names first)."""
    import csv

    fh = open(out, "w", encoding="utf-8", newline="") if isinstance(out, str | Path) else out
    try:
        w = csv.writer(fh, lineterminator="\n")
        for i, row in enumerate(rows):
            d = row.as_dict(quantiles)
            if header and i == 0:
                w.writerow(list(d))
            w.writerow([f"{v:.6g}" for v in d.values()])
        fh.flush()
    finally:
        if fh is not out:
            fh.close()


def jsonable(obj):
    """``obj`` with NumPy arrays and scalars made plain Python, non-finite floats None."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def write_json(path: str | Path, data: dict) -> None:
    """Write ``data`` as indented JSON (numpy scalars and arrays converted; NaN -> null)."""
    Path(path).write_text(json.dumps(jsonable(data), indent=2) + "\n")
