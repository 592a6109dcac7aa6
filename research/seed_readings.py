"""The seed's readings side by side: the numbers of the statement-by-statement table of
docs/seed-example.md ("The tension reading"), read off result files of
cases/goyal-writhing.yaml (zero force at the sliding end) and
cases/goyal-writhing-tension.yaml (dead tension).

    python -m research.seed_readings goyal.nc tension.nc

Event definitions: benchmarks/seed_events.py, plus
* Lk at onset: the linking number at the buckling onset;
* mid-span tangent ⊥: first output time the tangent at s = L/2 makes more than 90° with
  the original axis (the seed's Lu & Perkins condition, its 25-s snapshot);
* Wr steps: first output times Wr exceeds 0.5, 1.5, 2.5, 3.5 (a unit step of Wr passes
  through the half-integer);
* sliding end: z(L) at the given times.
"""
from __future__ import annotations

import sys

import numpy as np
import xarray as xr

from benchmarks.seed_events import events


def _first(t, mask):
    i = np.flatnonzero(np.asarray(mask))
    return float(t[i[0]]) if i.size else float("nan")


def _at(ds, name, t):
    return float(ds[name].sel(time=t, method="nearest"))


def readings(path) -> dict:
    ds = xr.open_dataset(path)
    t = ds.time.values
    out = events(ds)
    out["status"] = ds.attrs.get("hockle_status")
    out["lk_at_onset"] = _at(ds, "linking_number", out["buckling_onset"])
    out["tw_at_onset"] = _at(ds, "twist", out["buckling_onset"])
    out["lk_at_5s"] = _at(ds, "linking_number", 5.0)
    out["ut_peak"] = float(ds.energy_torsion.sel(time=out["torsion_peak"], method="nearest"))
    pos = ds.position.values                              # (time, node, xyz)
    mid = pos.shape[1] // 2
    tan = pos[:, mid + 1] - pos[:, mid - 1]
    tan /= np.linalg.norm(tan, axis=1)[:, None]
    angle = np.degrees(np.arccos(np.clip(tan[:, 2], -1, 1)))
    out["tangent_perp"] = _first(t, angle > 90.0)
    wr = ds.writhe.values
    for h in (0.5, 1.5, 2.5, 3.5):
        out[f"wr_above_{h}"] = _first(t, wr > h)
    fc = out["first_contact"]
    if np.isfinite(fc):
        out["wr_at_first_contact"] = _at(ds, "writhe", fc)
        after = (t >= fc) & (t <= fc + 5.0)
        out["wr_range_5s_after_contact"] = (float(wr[after].min()), float(wr[after].max()))
    for tt in (20.0, 25.0, 29.0, 32.0, 45.0):
        out[f"wr_{tt:g}"] = _at(ds, "writhe", tt)
        out[f"tw_{tt:g}"] = _at(ds, "twist", tt)
        out[f"contacts_{tt:g}"] = int(ds.contact_count.sel(time=tt, method="nearest"))
        out[f"zL_{tt:g}"] = float(pos[np.argmin(np.abs(t - tt)), -1, 2])
    on = out["buckling_onset"]
    out["zL_onset"] = float(pos[np.argmin(np.abs(t - on)), -1, 2])
    out["lk_end"] = float(ds.linking_number.values[-1])
    out["energy_at_end"] = {k: float(ds[k].values[-1]) for k in
                            ("energy_bending", "energy_torsion", "energy_kinetic")}
    return out


if __name__ == "__main__":
    for p in sys.argv[1:]:
        print(p)
        for k, v in readings(p).items():
            print(f"  {k}: {v}")
