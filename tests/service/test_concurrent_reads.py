"""Concurrent reads of result files: netCDF4-C and HDF5 are not thread-safe and the API's
routes run in a thread pool, so every NetCDF access of an API process holds
``service.store.NETCDF_LOCK``. Without it, concurrent result reads answered 500
("NetCDF: Can't open HDF5 attribute") or killed the API process."""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import pytest

from service import store
from svc_support import tiny_case

KEY = "concurrent-reads-key-0123456789"
AUTH = {"Authorization": f"Bearer {KEY}"}


#: the in-process service's settings (svc_support's ``settings`` and ``client`` fixtures)
SERVICE_SETTINGS = dict(api_keys=KEY)


@pytest.fixture(scope="module")
def finished_job(client, settings):
    from worker.tasks import run_job

    job = client.post("/v1/jobs", json=tiny_case("reads"), headers=AUTH).json()
    run_job(job["id"], "reads@test", settings)
    assert client.get(f"/v1/jobs/{job['id']}", headers=AUTH).json()["state"] == "successful"
    return client, job["id"]


def _paths(job_id: str) -> list[str]:
    base = f"/v1/jobs/{job_id}"
    return [f"{base}/summary", f"{base}/results/variables",
            f"{base}/results/variables/writhe", f"{base}/results/variables/dt",
            f"{base}/results/variables/position?s=0:0.5&xyz=x",
            f"/v1/ui/jobs/{job_id}/events"]


def test_every_netcdf_access_holds_the_lock(finished_job, monkeypatch):
    """Each result route opens its file with the lock held (checked at the open itself)."""
    client, job_id = finished_job
    import xarray as xr

    opened = []
    real_open = xr.open_dataset

    def checked_open(*args, **kwargs):
        # an RLock held by this thread can be taken again without blocking; held by no
        # one, it could too, so count the owner through the private flag of _is_owned
        opened.append(store.NETCDF_LOCK._is_owned())
        return real_open(*args, **kwargs)

    monkeypatch.setattr(xr, "open_dataset", checked_open)
    from service.dashboard import _EVENT_CACHE
    _EVENT_CACHE.clear()
    for path in _paths(job_id):
        assert client.get(path, headers=AUTH).status_code == 200, path
    assert opened and all(opened), opened


def test_concurrent_result_reads_all_answer(finished_job):
    """48 reads from 8 threads at once over the six result routes: every one answers 200
    with the same body as a lone read."""
    client, job_id = finished_job
    paths = _paths(job_id)
    lone = {p: client.get(p, headers=AUTH).content for p in paths}
    start = threading.Barrier(8)

    def hammer(k: int) -> list[tuple[str, int, bool]]:
        start.wait()
        out = []
        for i in range(6):
            p = paths[(k + i) % len(paths)]
            r = client.get(p, headers=AUTH)
            out.append((p, r.status_code, r.content == lone[p]))
        return out

    with ThreadPoolExecutor(8) as pool:
        answers = [a for batch in pool.map(hammer, range(8)) for a in batch]
    assert len(answers) == 48
    bad = [a for a in answers if a[1] != 200 or not a[2]]
    assert not bad, bad
