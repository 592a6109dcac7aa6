"""Time limits (issue 11, defect 3): the cost model against the measured contact runs and the
seed case, a job's own limit within the operator's maximum, and what a timed-out job keeps."""
from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from service.registry import Registry
from service.settings import CONTACT_CALIBRATION_DT, Settings
from svc_support import REPO, tiny_case


def tasks_app(settings: Settings):
    from service.app import create_app

    return create_app(settings)


# --- time limits: the cost model and a job's own limit -------------------------------------------
def test_cost_model_lets_the_seed_case_through(tmp_path):
    from solver.case import Case

    case = Case.from_file(REPO / "cases" / "goyal-writhing.yaml")
    assert case.contact is not None and (case.grid_points, case.n_steps) == (1001, 450)
    settings = Settings(data_dir=tmp_path)
    t_end = float(case.numerics.t_end)
    hard, soft, budget = settings.time_limits(case.grid_points, case.n_steps, True, t_end=t_end)
    # measured runs of this case on the 2-core machine (docs/contact.md section 4): 203 s and
    # 370 s with today's solver, 1272 s with the first round's; its contact phase ran 1.58 s per
    # 0.1-s step: the solver's own budget (the first limit it meets) clears all of them
    assert budget > 1272.0
    assert budget > 2 * 370.0
    assert budget > 1.5 * 1.58 * case.n_steps  # contact from t = 0 at the contact phase's pace
    assert hard == pytest.approx(60.0 + 5.6e-3 * 1001 * 450) and hard < settings.time_limit_max
    # the rule for smooth cases gives 150 s: it stopped the seed at t = 19.3 s (issue 11)
    assert settings.time_limits(case.grid_points, case.n_steps, False)[0] == pytest.approx(150.09)


@pytest.mark.parametrize("grid_points,wall_per_simulated_second", [
    # benchmarks/contact_scaling.py, the seed example at N segments in contact (docs/contact.md)
    (101, 2.8), (251, 3.9), (501, 5.0), (1001, 11.8), (2001, 28.2),
    # the seed's intertwined phase, 1.58 s per 0.1-s step
    (1001, 15.8),
])
def test_cost_model_covers_every_measured_contact_pace(tmp_path, grid_points,
                                                       wall_per_simulated_second):
    settings = Settings(data_dir=tmp_path)
    for t_end, dt in ((45.0, 0.1), (45.0, 1.0), (45.0, 0.01)):
        n_steps = round(t_end / dt)
        budget = settings.time_limits(grid_points, n_steps, True, t_end=t_end)[2]
        # a whole run in contact at that pace, with 1.5x to spare for a loaded machine
        assert budget > 1.5 * wall_per_simulated_second * t_end, (grid_points, dt)


def test_contact_limit_counts_simulated_time_not_only_nominal_steps(tmp_path):
    settings = Settings(data_dir=tmp_path)
    fine = settings.time_limits(1001, 450, True, t_end=45.0)
    coarse = settings.time_limits(1001, 45, True, t_end=45.0)  # dt = 1 s: contact sub-steps
    assert coarse == fine
    assert 45.0 / CONTACT_CALIBRATION_DT == 450
    smooth = settings.time_limits(1001, 45, False, t_end=45.0)
    assert smooth[0] < coarse[0]
    # capped, and a job's own limit replaces the derived one (capped too)
    assert settings.time_limits(10**6, 10**6, True, t_end=1e5)[0] == settings.time_limit_max
    assert settings.time_limits(1001, 450, True, t_end=45.0, requested=5000.0)[0] == 5000.0
    assert settings.time_limits(9, 5, requested=1e9)[0] == settings.time_limit_max


def test_job_asks_for_its_time_limit_within_the_maximum(tmp_path):
    settings = Settings(data_dir=tmp_path, broker_url="memory://", time_limit_max=7200.0)
    with TestClient(tasks_app(settings)) as client:
        asked = client.post("/v1/jobs", json=tiny_case("asked"), params={"time_limit": 5000})
        assert asked.status_code == 201, asked.text
        assert asked.json()["time_limit"] == 5000.0
        registry = Registry(settings.registry_url)
        try:
            job = registry.get(asked.json()["id"])
            assert job.soft_time_limit == pytest.approx(5000.0 * 0.95)
            assert job.wall_clock_budget == pytest.approx(5000.0 * 0.95 * 0.9)
        finally:
            registry.dispose()
        derived = client.post("/v1/jobs", json=tiny_case("derived")).json()
        assert derived["time_limit"] == pytest.approx(60.0 + 2e-4 * 9 * 5)
        for bad in ("7201", "0.5", "nan", "abc"):
            refused = client.post("/v1/jobs", json=tiny_case("too-long"),
                                  params={"time_limit": bad})
            assert refused.status_code == 422, (bad, refused.text)
            assert refused.headers["content-type"] == "application/problem+json"
            assert refused.json()["errors"][0]["loc"] == "query.time_limit"
        # the same Idempotency-Key with another limit is another request
        key = {"Idempotency-Key": "limit-key"}
        first = client.post("/v1/jobs", json=tiny_case("keyed"), params={"time_limit": 100},
                            headers=key)
        assert first.status_code == 201
        other = client.post("/v1/jobs", json=tiny_case("keyed"), params={"time_limit": 200},
                            headers=key)
        assert other.status_code == 422


def test_timed_out_job_keeps_its_partial_result_and_says_how_far(tmp_path):
    from svc_support import long_case
    from worker.tasks import run_job

    settings = Settings(data_dir=tmp_path, broker_url="memory://", progress_interval=0.0)
    with TestClient(tasks_app(settings)) as client:
        job = client.post("/v1/jobs", json=long_case("how-far", t_end=30.0)).json()
        registry = Registry(settings.registry_url)
        try:
            with registry.sessions.begin() as session:
                from service.registry import Job

                # past the solver's import and first steps (a few ms each), well before 30 s
                session.get(Job, job["id"]).wall_clock_budget = 3.0
        finally:
            registry.dispose()
        assert run_job(job["id"], "inproc@test", settings) == "failed:timeout"
        status = client.get(f"/v1/jobs/{job['id']}").json()
        assert (status["state"], status["reason"]) == ("failed", "timeout")
        assert status["result_available"] and status["result_partial"]
        assert 0 < status["progress"] < 100 and status["step"] > 0
        assert (f"wall-clock budget of 3 s reached at t = {status['sim_time']:.6g} s of 30 s "
                f"(step {status['step']}); the partial result is kept") in status["message"]
        assert "?time_limit=" in status["message"]
        summary = client.get(f"/v1/jobs/{job['id']}/summary").json()
        # the partial dataset holds the outputs (every 10 steps here) up to where it stopped
        assert summary["partial"] and 0 < summary["time"][-1] <= status["sim_time"]
