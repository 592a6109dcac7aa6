"""Small case builders shared by the solver tests (real `Case` objects, no fakes)."""
from __future__ import annotations

import numpy as np

from solver.case import Case

E, G, RHO, RHO_F = 1.25e7, 5.0e6, 1500.0, 1000.0


def kin(value=0.0, key="velocity"):
    return {key: value}


def clamped_end():
    return {"translation": [kin(), kin(), kin()],
            "rotation": [kin(key="angular_velocity")] * 3}


def free_end():
    return {"translation": [{"force": 0.0}] * 3, "rotation": [{"moment": 0.0}] * 3}


def smooth_pulse_table(amplitude, duration, n=401):
    """sin² pulse of the given peak value and duration, sampled as a table."""
    t = np.linspace(0.0, duration, n)
    return {"t": t.tolist(), "value": (amplitude * np.sin(np.pi * t / duration) ** 2).tolist()}


def make_case(*, n_segments=20, dt=0.01, t_end=0.1, rho_inf=0.5, diameter=0.02,
              length=1.0, start=None, end=None, fluid=None, gravity=None, forces=(),
              fields=("v", "omega", "f", "kappa", "position", "energies"), every=1,
              tolerance=1e-10, contact=None, max_dt_cuts=6):
    spec = {
        "schema_version": 1,
        "name": "test",
        "rod": {"length": length, "youngs_modulus": E, "shear_modulus": G,
                "density": RHO, "diameter": diameter},
        "boundary": {"start": start or clamped_end(), "end": end or clamped_end()},
        "distributed_forces": list(forces),
        "numerics": {"n_segments": n_segments, "dt": dt, "t_end": t_end,
                     "rho_inf": rho_inf, "max_dt_cuts": max_dt_cuts,
                     "newton": {"tolerance": tolerance, "max_iterations": 30}},
        "output": {"every": every, "fields": list(fields)},
    }
    if fluid is not None:
        spec["fluid"] = fluid
    if gravity is not None:
        spec["gravity"] = list(gravity)
    if contact is not None:
        spec["contact"] = contact
    return Case.model_validate(spec)
