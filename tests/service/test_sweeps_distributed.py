"""Parameter sweeps end to end on a real redis-server, a registry (PostgreSQL when a server
answers, else SQLite), the API and two Celery worker processes running the real solver: a
2 x 3 sweep over end tension and twist rate runs every member and combines them into one
dataset equal to the members' own results; a bad member value is refused before any job is
queued; dismissing a sweep dismisses its queued members; the client and hockle sweep --url.
"""
from __future__ import annotations

import copy
import io
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
import xarray as xr

from svc_support import Stack, make_stack, tiny_case, wait_until

pytestmark = pytest.mark.service

TENSION = "boundary.end.translation.2.force"
TWIST = "boundary.start.rotation.2.angular_velocity"
TERMINAL = ("successful", "failed", "dismissed")


def twisted_rod(name: str = "sweep-rod") -> dict:
    """A small twisted rod: 10 segments, clamped and turned at s = 0, its far end held
    sideways and pulled along its axis; 20 steps of 5 ms."""
    case = tiny_case(name, n_segments=10, dt=0.005, t_end=0.1)
    case["output"] = {"fields": ["kappa", "position", "energies", "topology"]}
    return case


@pytest.fixture(scope="module")
def stack(tmp_path_factory, redis_server, request):
    env = {"HOCKLE_BROKER_URL": redis_server.url, "HOCKLE_QUEUE": "sweeps"}
    try:
        env["HOCKLE_DATABASE_URL"] = request.getfixturevalue("pg_url")
    except pytest.skip.Exception:
        pass                                  # no PostgreSQL here: the SQLite registry
    stack = make_stack(tmp_path_factory, "sweep-stack", env)
    try:
        stack.start_api()
        stack.start_worker("w1", wait=False)
        stack.start_worker("w2", wait=False)
        for name in ("w1", "w2"):
            wait_until(lambda: stack._ready(name), 60, 0.2, f"worker {name}")
        yield stack
    finally:
        stack.close()


def _wait_sweep(stack: Stack, sweep_id: str, timeout: float = 120) -> dict:
    last = {}

    def done():
        last["s"] = stack.http.get(f"/v1/sweeps/{sweep_id}").json()
        return last["s"] if last["s"]["state"] in TERMINAL else None

    try:
        return wait_until(done, timeout, 0.2, f"sweep {sweep_id}")
    except AssertionError:
        raise AssertionError(f"sweep {sweep_id} is {last.get('s')}") from None


def _job_count(stack: Stack) -> int:
    return len(stack.http.get("/v1/jobs", params={"page_size": 500}).json()["jobs"])


def test_grid_sweep_runs_every_member_and_combines_their_results(stack: Stack, tmp_path):
    body = {"base": twisted_rod(), "combine": "grid",
            "parameters": {TENSION: [0.0, 2.0], TWIST: [1.0, 2.0, 3.0]}}
    before = _job_count(stack)
    response = stack.http.post("/v1/sweeps", json=body)
    assert response.status_code == 201, response.text
    sweep = response.json()
    assert response.headers["location"] == f"/v1/sweeps/{sweep['id']}"
    assert sweep["shape"] == [2, 3] and len(sweep["members"]) == 6
    assert sweep["state"] in ("accepted", "running")
    # one ordinary job per member, queued as POST /v1/jobs queues them
    assert _job_count(stack) == before + 6
    assert len({m["job_id"] for m in sweep["members"]}) == 6
    assert [m["values"] for m in sweep["members"][:2]] == [{TENSION: 0.0, TWIST: 1.0},
                                                           {TENSION: 0.0, TWIST: 2.0}]

    done = _wait_sweep(stack, sweep["id"])
    assert done["state"] == "successful" and done["progress"] == 100.0, done
    assert done["counts"] == {"successful": 6} and done["result_available"]
    workers = {stack.job(m["job_id"])["worker"] for m in done["members"]}
    assert workers == {"w1@test", "w2@test"}           # both workers took members

    response = stack.http.get(f"/v1/sweeps/{sweep['id']}/results",
                              params={"fields": "position"})
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "application/x-netcdf"
    path = tmp_path / "sweep.nc"
    path.write_bytes(response.content)
    with xr.open_dataset(path, engine="netcdf4") as combined:
        combined = combined.load()
    assert combined["writhe"].dims == (TENSION, TWIST, "time")
    assert combined["position"].dims == (TENSION, TWIST, "time", "s", "xyz")
    assert dict(combined.sizes) == {TENSION: 2, TWIST: 3, "time": 21, "s": 11, "xyz": 3,
                                    "event": combined.sizes["event"]}
    assert combined[TENSION].values.tolist() == [0.0, 2.0]
    assert combined[TWIST].values.tolist() == [1.0, 2.0, 3.0]
    assert combined.attrs["hockle_sweep_id"] == sweep["id"]
    assert (combined["member_status"].values == "successful").all()

    # every cell is its member's own result, as GET /v1/jobs/{id}/results serves it
    for member in done["members"]:
        own_path = tmp_path / f"{member['index']}.nc"
        own_path.write_bytes(stack.http.get(f"/v1/jobs/{member['job_id']}/results").content)
        with xr.open_dataset(own_path, engine="netcdf4") as own:
            own = own.load()
        cell = combined.sel(member["values"])
        assert str(cell["job_id"].values) == member["job_id"]
        assert int(cell["member_index"]) == member["index"]
        assert np.array_equal(cell["time"].values, own["time"].values)
        for name in ("energy_total", "energy_torsion", "twist", "writhe", "linking_number",
                     "position"):
            assert np.array_equal(cell[name].values, own[name].values), name
        spec = stack.http.get(f"/v1/jobs/{member['job_id']}/spec").json()
        assert spec["boundary"]["end"]["translation"][2][0]["force"] == member["values"][TENSION]
        assert spec["boundary"]["start"]["rotation"][2][0]["angular_velocity"] == \
            member["values"][TWIST]
    # the members differ: the linking number grows with the twist rate
    lk = np.abs(combined["linking_number"].isel(time=-1).values)
    assert lk[0, 0] < lk[0, 1] < lk[0, 2] and lk[1] == pytest.approx(lk[0])

    # the same sweep again is answered from those jobs (the dedupe of POST /v1/jobs)
    again = stack.http.post("/v1/sweeps", json=body).json()
    assert [m["job_id"] for m in again["members"]] == [m["job_id"] for m in done["members"]]
    assert again["state"] == "successful"
    # a dismissal of a finished sweep is refused
    finished = stack.http.delete(f"/v1/sweeps/{sweep['id']}")
    assert finished.status_code == 409 and finished.json()["type"].endswith("sweep-finished")


def test_a_bad_member_value_is_refused_before_any_job_is_queued(stack: Stack):
    before = _job_count(stack)
    body = {"base": twisted_rod("bad-sweep"), "combine": "grid",
            "parameters": {TENSION: [0.0, 1.0], "rod.diameter": [0.02, -0.01]}}
    response = stack.http.post("/v1/sweeps", json=body)
    assert response.status_code == 422, response.text
    problem = response.json()
    assert response.headers["content-type"] == "application/problem+json"
    assert problem["type"] == "urn:hockle:problem:invalid-sweep"
    assert [e["loc"] for e in problem["errors"]] == ["members[1].rod.diameter",
                                                     "members[3].rod.diameter"]
    assert problem["errors"][1]["msg"].startswith(
        f"member 3 ({TENSION} = 1.0, rod.diameter = -0.01): ")
    assert "nothing was queued" in problem["detail"]
    # a path that leads nowhere, and zipped lists of two lengths
    nowhere = stack.http.post("/v1/sweeps", json={
        "base": twisted_rod(), "parameters": {"boundary.end.translation.5.force": [1.0]}})
    assert nowhere.status_code == 422
    assert nowhere.json()["errors"][0]["loc"] == "parameters.boundary.end.translation.5.force"
    uneven = stack.http.post("/v1/sweeps", json={
        "base": twisted_rod(), "combine": "zip", "parameters": {TENSION: [0.0, 1.0],
                                                                 TWIST: [1.0]}})
    assert uneven.status_code == 422
    assert _job_count(stack) == before


def test_dismissing_a_sweep_dismisses_its_queued_members(stack: Stack, tmp_path):
    base = twisted_rod("dismiss-sweep")
    base["numerics"].update(n_segments=400, dt=0.01, t_end=20.0)   # ~5 s each alone
    base["output"] = {"every": 10, "fields": ["energies", "topology"]}
    body = {"base": base, "parameters": {TWIST: [1.0, 1.1, 1.2, 1.3, 1.4, 1.5]}}
    sweep = stack.http.post("/v1/sweeps", json=body).json()
    ids = [m["job_id"] for m in sweep["members"]]
    # two members running (two workers), four queued behind them
    wait_until(lambda: sum(stack.job(j)["state"] == "running" for j in ids) == 2, 60, 0.1,
               "two members to run")
    response = stack.http.delete(f"/v1/sweeps/{sweep['id']}")
    assert response.status_code == 202, response.text     # members were running
    after = response.json()
    assert after["dismissed"] is True
    # the queued members are dismissed at once (a running one may be done stopping too)
    assert after["counts"].get("dismissed", 0) >= 4, after["counts"]
    done = _wait_sweep(stack, sweep["id"], 60)
    assert done["state"] == "dismissed" and done["counts"] == {"dismissed": 6}
    never_ran = 0
    for member in done["members"]:
        job = stack.job(member["job_id"])
        assert job["state"] == "dismissed" and job["reason"] == "cancelled_by_user"
        never_ran += job["attempts"] == 0 and job["started"] is None
    assert never_ran == 4                                  # the four queued ones never started
    # the combined dataset marks them; the two stopped members keep their partial series
    response = stack.http.get(f"/v1/sweeps/{sweep['id']}/results")
    assert response.status_code == 200
    with _open_bytes(response.content, tmp_path) as ds:
        assert (ds["member_status"].values == "dismissed").all()
        reached = ds["member_t_reached"].values
        assert np.isfinite(reached).sum() >= 2 and np.nanmax(reached) < 20.0


def _open_bytes(content: bytes, directory):
    path = directory / "downloaded.nc"
    path.write_bytes(content)
    return xr.open_dataset(path, engine="netcdf4")


def test_client_and_hockle_sweep_on_the_service(stack: Stack, tmp_path):
    from hockle.cli import main
    from service.client import HockleAPIError, HockleClient

    base = twisted_rod("client-sweep")
    with HockleClient(stack.url) as client:
        seen = []
        status = client.sweep(base, {TENSION: [0.5, 1.5], TWIST: [2.5, 3.5]}, combine="zip",
                              wait=True, poll_interval=0.2,
                              on_progress=lambda s: seen.append(s.state))
        assert status.state == "successful" and seen[-1] == "successful"
        ds = client.sweep_dataset(status.id)
        assert ds["writhe"].dims == ("member", "time")
        assert ds[TENSION].values.tolist() == [0.5, 1.5]
        with pytest.raises(HockleAPIError) as err:
            client.sweep(base, {"rod.length": [1.0, -1.0]})
        assert err.value.status == 422 and err.value.errors[0]["loc"] == "members[1].rod.length"

    path = tmp_path / "base.json"
    import json

    path.write_text(json.dumps(copy.deepcopy(base)))
    out = tmp_path / "cli-sweep.nc"
    buffer, errors = io.StringIO(), io.StringIO()
    with redirect_stdout(buffer), redirect_stderr(errors):
        code = main(["sweep", str(path), "--set", f"{TENSION}=0.25,0.75", "--url", stack.url,
                     "--wait", "--poll", "0.2", "-o", str(out)])
    assert code == 0, buffer.getvalue() + errors.getvalue()
    assert "successful" in buffer.getvalue()
    with xr.open_dataset(out, engine="netcdf4") as ds:
        assert ds["energy_total"].dims == (TENSION, "time")
