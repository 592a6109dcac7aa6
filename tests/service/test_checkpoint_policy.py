"""When a running job's checkpoint is stored (worker.tasks.CheckpointPolicy): by wall time, by
simulated progress and at the first step in contact, so that a killed job loses at most about
half a minute with the defaults. In-process: the worker's task code and the real solver."""
from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.settings import Settings
from svc_support import tiny_case
from worker.tasks import CheckpointPolicy


def test_the_policy_stores_by_wall_time_progress_and_first_contact():
    policy = CheckpointPolicy(interval=30.0, progress=0.1, t_end=45.0, last_wall=0.0)
    assert policy.due(1.0, 0, now=10.0) is None
    assert policy.due(1.0, 0, now=30.0) == "wall_time"
    assert policy.due(4.5, 0, now=10.0) == "progress"          # 10 % of 45 s
    assert policy.due(1.0, 3, now=10.0) == "first_contact"
    policy.stored(18.2, 3, now=10.0)
    assert policy.due(18.3, 5, now=11.0) is None                 # still in contact: once
    assert policy.due(22.7, 5, now=11.0) == "progress"
    off = CheckpointPolicy(interval=30.0, progress=0.0, t_end=45.0, last_wall=0.0)
    assert off.due(44.0, 0, now=29.0) is None


def test_the_defaults_lose_at_most_half_a_minute():
    settings = Settings()
    assert settings.checkpoint_interval <= 30.0 and settings.checkpoint_progress == 0.1


@pytest.fixture
def client_settings(tmp_path):
    return Settings(data_dir=tmp_path, broker_url="memory://", progress_interval=0.0,
                    checkpoint_interval=1e6, checkpoint_progress=0.4)


def test_a_job_stores_checkpoints_by_simulated_progress(client_settings, monkeypatch):
    """Wall-time checkpoints off in effect (1e6 s): a 5-step run to 0.05 s with a checkpoint
    every 40 % of the run stores one at t = 0.02 s and one at 0.04 s."""
    from service.store import ResultStore
    from worker import tasks

    monkeypatch.setattr(tasks, "CHECKPOINT_OFFER_INTERVAL", 0.0)   # offered at every step
    stored = []
    original = ResultStore.write_checkpoint

    def spy(self, job_id, data):
        from solver.checkpoint import Checkpoint

        stored.append(round(Checkpoint.header(data)["t"], 9))
        return original(self, job_id, data)

    monkeypatch.setattr(ResultStore, "write_checkpoint", spy)
    with TestClient(create_app(client_settings)) as client:
        response = client.post("/v1/jobs", json=tiny_case("by-progress"))
        assert response.status_code == 201, response.text
        job_id = response.json()["id"]
        tasks.run_job(job_id, "policy@test", client_settings)
        assert client.get(f"/v1/jobs/{job_id}").json()["state"] == "successful"
    assert stored == [0.02, 0.04]
