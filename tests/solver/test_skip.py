"""A case pays only for what it has (issue 5, "skip what a case does not need").

Each test replaces the expensive routine with a counter (or a trap) and runs the real
solver: no contact search structure without ``contact`` (or while no two distant points
can be within the tolerance), topology only at output steps, output fields nobody asked
for neither computed nor stored, no fluid terms without a fluid, no pose-dependent load
work without pose-dependent loads.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import solver.contact as contact_mod
import solver.contact.geometry as geometry_mod
import solver.contact.model as model_mod
import solver.recording as recording_mod
import solver.simulation as sim_mod
import solver.topology as topology_mod
from solver import Case, integrate

SEED = Path(__file__).resolve().parents[2] / "cases" / "goyal-writhing.yaml"


def seed_spec(n_segments=40, t_end=0.5, fields=("energies",), every=1, contact=True,
              fluid=True):
    spec = Case.from_file(SEED).model_dump(mode="json")
    spec["numerics"].pop("ds")
    spec["numerics"].update(n_segments=n_segments, t_end=t_end)
    spec["output"].update(fields=list(fields), every=every)
    if not contact:
        spec.pop("contact")
    if not fluid:
        spec.pop("fluid")
    return spec


class Trap:
    """Counts calls and either fails or forwards to the original; ``method()`` gives a
    function that can replace a method (a plain function binds ``self``)."""

    def __init__(self, original=None, fail=False):
        self.original, self.fail, self.calls = original, fail, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        if self.fail:
            raise AssertionError("called although the case does not need it")
        return self.original(*args, **kwargs)

    def method(self):
        def bound(*args, **kwargs):
            return self(*args, **kwargs)
        return bound


def test_no_search_structure_without_contact(monkeypatch):
    trap = Trap(fail=True)
    monkeypatch.setattr(geometry_mod, "cKDTree", trap)
    monkeypatch.setattr(contact_mod.SelfContact, "may_touch", Trap(fail=True).method())
    monkeypatch.setattr(contact_mod.SelfContact, "may_touch_unchecked",
                        Trap(fail=True).method())
    ds = integrate(Case.model_validate(seed_spec(contact=False, fields=("energies", "position"))))
    assert ds.attrs["hockle_status"] == "completed" and trap.calls == 0


def test_no_tree_while_no_contact_is_possible(monkeypatch):
    # the seed's rod with contact configured, early in the twist: straight, so the O(N)
    # pre-test rules every pair out and no k-d tree is ever built (on this grid of at
    # most ALL_PAIRS_NODES nodes the pre-test and the pairs are one compiled call,
    # _search_all_pairs)
    assert 41 <= geometry_mod.ALL_PAIRS_NODES
    tree = Trap(original=geometry_mod.cKDTree)
    monkeypatch.setattr(geometry_mod, "cKDTree", tree)
    pretest = Trap(original=model_mod._search_all_pairs)
    monkeypatch.setattr(model_mod, "_search_all_pairs", pretest)
    ds = integrate(Case.model_validate(seed_spec(contact=True)))
    assert ds.attrs["hockle_status"] == "completed"
    assert pretest.calls > 0 and tree.calls == 0


def test_topology_only_at_output_steps(monkeypatch):
    writhe = Trap(original=topology_mod.writhe)
    monkeypatch.setattr(topology_mod, "writhe", writhe)
    ds = integrate(Case.model_validate(seed_spec(t_end=1.0, every=5, fields=("topology",))))
    n_steps = ds.sizes["step"]
    assert n_steps == 10 and ds.sizes["time"] == 3          # t = 0, 0.5, 1.0
    assert writhe.calls == ds.sizes["time"]


def test_fields_nobody_asked_for_are_neither_computed_nor_stored(monkeypatch):
    monkeypatch.setattr(recording_mod, "energies", Trap(fail=True))
    monkeypatch.setattr(topology_mod, "writhe", Trap(fail=True))
    monkeypatch.setattr(topology_mod, "twist", Trap(fail=True))
    ds = integrate(Case.model_validate(seed_spec(fields=("kappa",))))
    assert "kappa" in ds
    for name in ("v", "omega", "f", "moment", "position", "orientation", "writhe",
                 "twist", "linking_number", "contact_count"):
        assert name not in ds, name
    assert not any(name.startswith("energy") for name in ds.data_vars)


def _drag_share(run):
    """The Morison drag's part of the residual at a state moving sideways: the residual
    of the run's first step with the compiled residual's drag switch as the case set it,
    minus the same with the switch off (the switch, ``rod_data.has_drag``, is what the
    compiled residual branches on)."""
    from solver.scheme import BACKWARD_EULER

    system = run.system
    system.begin_step(0.01, BACKWARD_EULER, 0.01, run.state.Y, run.state.Ydot, run.state.F_old, run.state.bc,
                      q_old=run.state.q, r_old=run.state.r, v_old_global=run.state.v_global)
    Y = run.state.Y.copy()
    Y[:, 0] = 0.1                                       # v1 = 0.1 m/s everywhere
    with_switch = system.residual(Y)[0]
    saved = system.rod_data
    system.rod_data = saved._replace(has_drag=False)
    try:
        without = system.residual(Y)[0]
    finally:
        system.rod_data = saved
    return with_switch - without


def test_no_fluid_terms_without_a_fluid():
    run = sim_mod.RodRun(Case.model_validate(seed_spec(contact=False, fluid=False)))
    assert not run.loads.has_drag and run.system.rod_data.has_drag is False
    assert np.all(_drag_share(run) == 0.0)
    ds = integrate(Case.model_validate(seed_spec(contact=False, fluid=False)))
    assert ds.attrs["hockle_status"] == "completed"


def test_fluid_terms_are_used_with_a_fluid():
    # the counterpart of the test above, so that the switch is known to gate the term
    run = sim_mod.RodRun(Case.model_validate(seed_spec(contact=False, fluid=True, t_end=0.2)))
    assert run.loads.has_drag and run.system.rod_data.has_drag is True
    assert np.max(np.abs(_drag_share(run))) > 0.0


@pytest.mark.parametrize("gravity", [None, [0.0, 0.0, -9.81]])
def test_pose_inside_newton_only_for_pose_dependent_loads(gravity):
    spec = seed_spec(contact=False, t_end=0.2)
    spec["distributed_forces"] = []       # the seed's perturbation is a global-frame load
    if gravity is not None:
        spec["gravity"] = gravity
    run = sim_mod.RodRun(Case.model_validate(spec))
    assert run.system.needs_pose is (gravity is not None)
    run.advance(0.1)
    assert np.all(np.isfinite(run.state.Y))
