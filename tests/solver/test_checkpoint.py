"""Checkpoints and resume (solver.checkpoint): a run resumed from a checkpoint repeats the
uninterrupted run to the last bit, with self-contact (fixed steps, Newton's factorisation
reused across steps) and with error-controlled steps; bad checkpoints are refused with
the reason."""
import numpy as np
import pytest

from rodcases import clamped_end, free_end, make_case
from solver import integrate
from solver.checkpoint import Checkpoint, CheckpointError, resume_key
from test_contact_run import fast_writhing_case


def run_with_checkpoint_at(case, t_pick):
    """The uninterrupted run and the serialised checkpoint of its first accepted step at
    or after t_pick (s)."""
    saved = {}

    def keep(ck):
        if "data" not in saved and ck.t >= t_pick:
            saved["data"] = ck.dumps()

    ds = integrate(case, checkpoint=keep, checkpoint_interval=0.0)
    return ds, saved["data"]


def assert_identical(a, b):
    assert list(a.data_vars) == list(b.data_vars)
    np.testing.assert_array_equal(a.time.values, b.time.values)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert a.attrs["hockle_status"] == b.attrs["hockle_status"]


def test_resume_in_contact_repeats_the_run_bit_for_bit():
    case = fast_writhing_case(6.9)
    full, data = run_with_checkpoint_at(case, 6.6)
    head = Checkpoint.header(data)
    assert head["case_hash"] == resume_key(case) and head["t"] >= 6.6
    ck = Checkpoint.loads(data, case)
    assert ck.run.contact_count > 0                      # in contact at the checkpoint
    steps_before = ck.step
    resumed = integrate(case, resume=ck)
    assert_identical(full, resumed)
    assert resumed.attrs["hockle_resumed_at"] == pytest.approx(ck.t)
    # nothing before the checkpoint was recomputed: the resumed run took the remaining steps
    assert resumed.sizes["step"] == full.sizes["step"] and steps_before > 0
    # the checkpoint object is untouched by the resume (another resume gives the same)
    assert_identical(full, integrate(case, resume=ck))
    # a checkpoint pickled before the step's data were one StepTerms resumes the same
    assert ck.run.system.step.candidates is not None
    assert_identical(full, integrate(case, resume=Checkpoint.loads(old_layout(ck), case)))


def old_layout(ck) -> bytes:
    """The checkpoint's bytes with its RodSystem pickled as before StepTerms: the step's
    data as the system's own attributes (``step_data``, ``_glob_force`` ...)."""
    from solver.scheme import _OLD_STEP_NAMES, RodSystem

    def old_state(system):
        state = new_state(system)
        step = state.pop("step")
        state.update({name: getattr(step, new) for name, new in _OLD_STEP_NAMES.items()})
        return state

    new_state = RodSystem.__getstate__
    RodSystem.__getstate__ = old_state
    try:
        data = ck.dumps()
    finally:
        RodSystem.__getstate__ = new_state
    assert b"step_data" in data and b"StepTerms" not in data
    return data


@pytest.mark.parametrize("formulation", ["goyal", "centreline"])
def test_resume_of_an_error_controlled_run(formulation):
    case = make_case(n_segments=12, dt=0.002, t_end=0.3, start=clamped_end(), end=free_end(),
                     forces=[{"value": [0.0, 2.0, 0.0], "start": 0.0}])
    spec = case.model_dump(mode="json")
    spec["numerics"]["tolerance"] = {"relative": 1e-3, "absolute": 1e-6}
    spec["numerics"]["formulation"] = formulation
    spec["output"]["interval"] = 0.05
    case = type(case).model_validate(spec)
    full, data = run_with_checkpoint_at(case, 0.12)
    resumed = integrate(case, resume=Checkpoint.loads(data, case))
    assert_identical(full, resumed)


def test_bad_checkpoints_are_refused_with_the_reason():
    load = [{"value": [0.0, 1.0, 0.0], "start": 0.0}]
    case = make_case(n_segments=6, dt=0.01, t_end=0.05, end=free_end(), forces=load)
    other = make_case(n_segments=6, dt=0.01, t_end=0.06, end=free_end(), forces=load)
    _, data = run_with_checkpoint_at(case, 0.02)
    with pytest.raises(CheckpointError, match="another case"):
        Checkpoint.loads(data, other)
    with pytest.raises(CheckpointError, match="another case"):
        integrate(other, resume=Checkpoint.loads(data))
    with pytest.raises(CheckpointError, match="not a hockle checkpoint"):
        Checkpoint.loads(b"\x89HDF\r\n\x1a\n garbage")
    with pytest.raises(CheckpointError, match="version"):
        Checkpoint.loads(data.replace(b'"version": 1', b'"version": 99', 1))


def test_a_stopped_run_leaves_a_checkpoint_that_finishes_it(tmp_path):
    """Stopped half-way (a should_stop callback, as Ctrl-C in hockle run): the checkpoint
    handed out at the stop continues to the uninterrupted result."""
    load = [{"value": [0.0, 1.0, 0.0], "start": 0.0}]
    case = make_case(n_segments=8, dt=0.01, t_end=0.2, end=free_end(), forces=load)
    full = integrate(case)
    saved = []
    steps = []
    part = integrate(case, progress=lambda p: steps.append(p.step),
                    should_stop=lambda: len(steps) >= 7,
                    checkpoint=lambda ck: saved.append(ck.dumps()), checkpoint_interval=1e9)
    assert part.attrs["hockle_status"] == "stopped" and len(saved) == 1
    ck = Checkpoint.loads(saved[0], case)
    assert ck.step == 7 and ck.t == pytest.approx(0.07)
    assert_identical(full, integrate(case, resume=ck))


def test_a_checkpoint_of_an_older_solver_is_refused_with_the_reason():
    """A checkpoint whose run lacks an attribute this code's runs have (written before the
    attribute existed) is refused up front, not left to fail inside a step."""
    load = [{"value": [0.0, 1.0, 0.0], "start": 0.0}]
    case = make_case(n_segments=6, dt=0.01, t_end=0.05, end=free_end(), forces=load)
    _, data = run_with_checkpoint_at(case, 0.02)
    ck = Checkpoint.loads(data, case)
    del ck.run.loads.extra                       # as written before extra_force existed
    with pytest.raises(CheckpointError, match="another version of the solver.*LoadModel.extra"):
        Checkpoint.loads(ck.dumps(), case)
