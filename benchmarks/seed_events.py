"""Event times of the seed example, read off a result dataset (shared by the seed
benchmark, the sensitivity study and docs/seed-example.md).

Definitions (ours; the seed reads them off its figures):
* buckling onset: first output time at which the bending energy exceeds 1 % of the
  torsional energy;
* torsional-energy peak: time of the largest torsional energy before first contact;
* first self-contact: first output time with contact_count > 0;
* Wr after first contact: writhe 1 s after first contact;
* Wr > 1.5 and Wr > 2: first output times the writhe exceeds them (intertwining);
* max |Tw + Wr - Lk| and the smallest surface gap over the whole run.
"""
from __future__ import annotations

import numpy as np


def _first(ds, mask):
    idx = np.flatnonzero(np.asarray(mask))
    return float(ds.time[idx[0]]) if idx.size else float("nan")


def events(ds) -> dict:
    """Event times (s) and extreme values of a seed-example dataset (needs energies,
    topology and contact fields)."""
    ub, ut = ds.energy_bending.values, ds.energy_torsion.values
    out = {"buckling_onset": _first(ds, ub > 0.01 * ut)}
    contact = ds.contact_count.values > 0
    out["first_contact"] = _first(ds, contact)
    before = np.ones_like(contact) if np.isnan(out["first_contact"]) else \
        ds.time.values < out["first_contact"]
    out["torsion_peak"] = float(ds.time.values[np.argmax(np.where(before, ut, -np.inf))])
    if np.isnan(out["first_contact"]):
        out["writhe_after_contact"] = float("nan")
    else:
        out["writhe_after_contact"] = float(
            ds.writhe.sel(time=out["first_contact"] + 1.0, method="nearest"))
    out["writhe_above_1_5"] = _first(ds, ds.writhe.values > 1.5)
    out["writhe_above_2"] = _first(ds, ds.writhe.values > 2.0)
    out["max_topology_error"] = float(np.nanmax(ds.topology_error.values))
    gaps = ds.min_surface_gap.values
    out["min_surface_gap"] = float(np.min(gaps[np.isfinite(gaps)])) if np.any(np.isfinite(gaps)) \
        else float("inf")
    out["t_reached"] = float(ds.time[-1])
    return out
