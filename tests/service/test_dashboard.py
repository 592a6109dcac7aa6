"""The dashboard at /ui/ without a browser (issue 44): its files, headers and the /v1/ui routes.

The browser tests are in test_dashboard_browser.py.
"""
from __future__ import annotations

import re
from urllib.parse import urljoin

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.dashboard import CSP, STATIC_DIR
from service.settings import Settings
from svc_support import tiny_case

KEY = "dashboard-key-0123456789abcdef"
AUTH = {"Authorization": f"Bearer {KEY}"}
OWN_FILES = ("index.html", "app.js", "view3d.js", "app.css")


#: the in-process service's settings (svc_support's ``settings`` and ``client`` fixtures)
SERVICE_SETTINGS = dict(api_keys=KEY)


def _run(settings, job_id):
    from worker.tasks import run_job

    return run_job(job_id, "ui@test", settings)


def test_pages_are_public_and_carry_the_csp(client):
    assert client.get("/ui", follow_redirects=False).headers["location"].endswith("/ui/")
    page = client.get("/ui/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert page.headers["content-security-policy"] == CSP
    assert "script-src 'self'" in CSP and "unsafe-inline" not in CSP and "default-src 'none'" in CSP
    assert page.headers["x-content-type-options"] == "nosniff"
    html = page.text
    # no inline script or style, no event-handler attribute
    assert not re.search(r"<script(?![^>]*\bsrc=)[^>]*>", html), html
    assert "<style" not in html and " style=" not in html
    assert not re.search(r"\son[a-z]+\s*=", html)
    refs = re.findall(r"""(?:src|href)="([^"#]+)\"""", html)
    assert {"vendor/uPlot.iife.min.js", "app.js", "view3d.js", "app.css"} <= set(refs)
    for ref in refs:
        if ref.startswith("data:"):
            continue
        asset = client.get(urljoin("/ui/", ref))
        assert asset.status_code == 200 and asset.content, ref
        assert asset.headers["content-security-policy"] == CSP


def test_own_files_name_no_other_host_and_never_use_inner_html():
    for name in OWN_FILES:
        text = (STATIC_DIR / name).read_text()
        assert not re.search(r"(?:https?:)?//[A-Za-z0-9-]+\.[A-Za-z]", text.replace("://", "")) \
            and "http://" not in text and "https://" not in text, name
        assert "innerHTML" not in text and "outerHTML" not in text and "insertAdjacentHTML" \
            not in text and "document.write" not in text, name
        assert "localStorage" not in text, name
    # the vendored library with its licence beside it
    vendor = STATIC_DIR / "vendor"
    assert "MIT License" in (vendor / "uPlot.LICENSE").read_text()
    assert "uPlot" in (vendor / "uPlot.iife.min.js").read_text()


def test_config_says_whether_keys_are_set(client, tmp_path):
    assert client.get("/ui/config").json()["auth"] is True
    with TestClient(create_app(Settings(data_dir=tmp_path, broker_url="memory://"))) as open_:
        assert open_.get("/ui/config").json()["auth"] is False
        assert open_.get("/v1/ui/jobs").status_code == 200


def test_ui_routes_need_a_known_key(client):
    for path in ("/v1/ui/jobs", "/v1/ui/jobs/x/events", "/v1/ui/sweeps/x/map"):
        assert client.get(path).status_code == 401
        assert client.get(path, headers={"Authorization": "Bearer wrong-key"}).status_code == 401
    assert client.post("/v1/ui/validate", json=tiny_case()).status_code == 401
    assert "/v1/ui/jobs" not in client.get("/openapi.json").json()["paths"]


def test_ui_routes_refuse_an_unknown_query_parameter(client):
    """As on the /v1 API: a misspelt parameter is a 422 naming it, not ignored."""
    bad = client.get("/v1/ui/jobs?page_sise=5", headers=AUTH)
    assert bad.status_code == 422
    [err] = bad.json()["errors"]
    assert err["loc"] == "query.page_sise" and "page_size" in err["msg"]
    for path in ("/v1/ui/jobs/x/events?x=1", "/v1/ui/sweeps/x/map?x=1"):
        assert client.get(path, headers=AUTH).status_code == 422, path
    assert client.get("/v1/ui/jobs?page_size=5", headers=AUTH).status_code == 200


def test_job_list_answers_304_until_it_changes(client):
    first = client.get("/v1/ui/jobs", headers=AUTH)
    assert first.status_code == 200
    etag = first.headers["etag"]
    again = client.get("/v1/ui/jobs", headers={**AUTH, "If-None-Match": etag})
    assert again.status_code == 304 and not again.content
    created = client.post("/v1/jobs", json=tiny_case("etag"), headers=AUTH)
    assert created.status_code in (200, 201)
    changed = client.get("/v1/ui/jobs", headers={**AUTH, "If-None-Match": etag})
    assert changed.status_code == 200 and changed.headers["etag"] != etag
    assert created.json()["id"] in [j["id"] for j in changed.json()["jobs"]]
    bad = client.get("/v1/ui/jobs", params={"status": "sleeping"}, headers=AUTH)
    assert bad.status_code == 422 and bad.json()["errors"][0]["loc"] == "query.status"


def test_validate_is_a_dry_run_with_the_submissions_422(client):
    before = len(client.get("/v1/ui/jobs", params={"page_size": 500}, headers=AUTH).json()["jobs"])
    case = tiny_case("dry run")
    case["rod"]["youngs_modulus"] = -1.0
    answer = client.post("/v1/ui/validate", json=case, headers=AUTH)
    submitted = client.post("/v1/jobs", json=case, headers=AUTH)
    assert answer.status_code == submitted.status_code == 422
    assert answer.json()["errors"] == submitted.json()["errors"]
    assert [e["loc"] for e in answer.json()["errors"]] == ["rod.youngs_modulus"]
    yaml_text = b"schema_version: 1\nname: y\nrod: {length: 1}\n"
    answer = client.post("/v1/ui/validate", content=yaml_text,
                         headers={**AUTH, "Content-Type": "application/yaml"})
    assert answer.status_code == 422
    assert "rod.youngs_modulus" in [e["loc"] for e in answer.json()["errors"]]
    good = client.post("/v1/ui/validate", json=tiny_case("fine"), headers=AUTH)
    assert good.status_code == 200 and good.json()["valid"] and good.json()["grid_points"] == 9
    after = len(client.get("/v1/ui/jobs", params={"page_size": 500}, headers=AUTH).json()["jobs"])
    assert after == before


def test_events_and_sweep_map(client, settings):
    case = tiny_case("events")
    case["numerics"].update(n_segments=8, t_end=0.3)
    job = client.post("/v1/jobs", json=case, headers=AUTH).json()
    assert client.get(f"/v1/ui/jobs/{job['id']}/events", headers=AUTH).status_code == 404
    _run(settings, job["id"])
    events = client.get(f"/v1/ui/jobs/{job['id']}/events", headers=AUTH).json()
    names = [e["name"] for e in events["events"]]
    assert names[:2] == ["buckling_onset", "first_contact"]
    # the words hockle run prints for each (solver.results.event_label)
    assert [e["label"] for e in events["events"]][:2] == ["buckling onset", "first contact"]
    assert all(set(e) >= {"time", "index", "twist", "writhe", "linking_number"}
               for e in events["events"])
    summary = client.get(f"/v1/jobs/{job['id']}/summary", headers=AUTH).json()
    for event in events["events"]:
        if event["index"] is not None:
            assert event["time"] == pytest.approx(summary["time"][event["index"]])

    sweep = client.post("/v1/sweeps", headers=AUTH, json={
        "base": tiny_case("map"),
        "parameters": {"boundary.start.rotation.2.angular_velocity": [1.0, 2.0]}}).json()
    empty = client.get(f"/v1/ui/sweeps/{sweep['id']}/map", headers=AUTH).json()
    assert [m["event_time"] for m in empty["members"]] == [{}, {}]
    for member in sweep["members"]:
        _run(settings, member["job_id"])
    mapped = client.get(f"/v1/ui/sweeps/{sweep['id']}/map", headers=AUTH).json()
    assert mapped["shape"] == [2] and mapped["parameters"][0]["values"] == [1.0, 2.0]
    assert [m["state"] for m in mapped["members"]] == ["successful", "successful"]
    assert all("buckling_onset" in m["event_time"] for m in mapped["members"])
    # the map's event selector shows hockle run's labels, not the raw names
    assert mapped["event_labels"]["buckling_onset"] == "buckling onset"
    assert set(mapped["event_labels"]) == set(mapped["events"])
    assert client.get("/v1/ui/sweeps/nope/map", headers=AUTH).status_code == 404


def test_seabed_grid_for_the_3d_view(client, settings, tmp_path):
    """GET /v1/ui/jobs/{id}/seabed: the bottom the 3-D view draws under the rod. A flat
    bottom is its elevation everywhere; a bathymetry that is a plane (z = -0.5 + x + 2 y at
    the corners of its 10-cm grid) is that plane at every point of the view's grid inside
    the bathymetry's grid and, outside it, the plane at the nearest edge (held); the grid
    covers the rod at every stored time with at least 5 diameters to spare; null without a
    seabed; 404 before the result, 422 naming query.n outside 2..65, 401 without the key."""
    import numpy as np
    import xarray as xr

    def plane(x, y):
        return -0.5 + np.clip(x, -0.05, 0.05) + 2.0 * np.clip(y, -0.05, 0.05)

    gx = gy = [-0.05, 0.05]
    bathymetry = {"x": gx, "y": gy, "z": [[float(plane(a, b)) for b in gy] for a in gx]}
    grids = {}
    for kind, seabed in (("elevation", {"elevation": -0.25}),
                         ("bathymetry", {"bathymetry": bathymetry}), ("none", None)):
        case = tiny_case(f"seabed {kind}")
        case["numerics"].update(n_segments=8, t_end=0.1)
        if seabed is not None:
            case["seabed"] = seabed
        job = client.post("/v1/jobs", json={**case}, headers=AUTH).json()
        if kind == "elevation":
            assert client.get(f"/v1/ui/jobs/{job['id']}/seabed",
                              headers=AUTH).status_code == 404
        _run(settings, job["id"])
        answer = client.get(f"/v1/ui/jobs/{job['id']}/seabed", params={"n": 9}, headers=AUTH)
        assert answer.status_code == 200, answer.text
        grids[kind] = answer.json()["seabed"]
        if kind == "elevation":
            result = client.get(f"/v1/jobs/{job['id']}/results", headers=AUTH)
            (tmp_path / "r.nc").write_bytes(result.content)
            with xr.open_dataset(tmp_path / "r.nc") as ds:
                pos = ds["position"].values.reshape(-1, 3)
            for name in ("n=1", "n=66"):
                bad = client.get(f"/v1/ui/jobs/{job['id']}/seabed", params={"n": name[2:]},
                                 headers=AUTH)
                assert bad.status_code == 422 and bad.json()["errors"][0]["loc"] == "query.n"
            assert client.get(f"/v1/ui/jobs/{job['id']}/seabed").status_code == 401
    assert grids["none"] is None
    flat = grids["elevation"]
    x, y, z = (np.asarray(flat[k]) for k in ("x", "y", "z"))
    assert flat["kind"] == "elevation" and x.shape == y.shape == (9,) and z.shape == (9, 9)
    assert np.all(z == -0.25)
    assert x[0] <= pos[:, 0].min() - 0.1 and x[-1] >= pos[:, 0].max() + 0.1
    assert y[0] <= pos[:, 1].min() - 0.1 and y[-1] >= pos[:, 1].max() + 0.1
    bed = grids["bathymetry"]
    x, y, z = (np.asarray(bed[k]) for k in ("x", "y", "z"))
    assert bed["kind"] == "bathymetry" and x[0] < -0.05 and x[-1] > 0.05 and y[0] < -0.05
    np.testing.assert_allclose(z, plane(x[:, None], y[None, :]), atol=1e-12)


def test_paraview_download_is_the_export_zipped(client, settings, tmp_path, monkeypatch):
    """The job page's ParaView download: a zip of the .pvd and its .vtu frames written by
    service.export, whose positions are the result's; at most PARAVIEW_MAX_FRAMES frames."""
    import io
    import zipfile

    import meshio
    import numpy as np
    import xarray as xr

    import service.dashboard as dashboard
    from service.export import read_pvd

    case = tiny_case("paraview")
    job = client.post("/v1/jobs", json=case, headers=AUTH).json()
    assert client.get(f"/v1/ui/jobs/{job['id']}/paraview", headers=AUTH).status_code == 404
    _run(settings, job["id"])
    monkeypatch.setattr(dashboard, "PARAVIEW_MAX_FRAMES", 3)
    answer = client.get(f"/v1/ui/jobs/{job['id']}/paraview", headers=AUTH)
    assert answer.status_code == 200 and answer.headers["content-type"] == "application/zip"
    zipfile.ZipFile(io.BytesIO(answer.content)).extractall(tmp_path)
    frames = read_pvd(tmp_path / f"{job['id']}.pvd")
    result = client.get(f"/v1/jobs/{job['id']}/results", headers=AUTH)
    (tmp_path / "r.nc").write_bytes(result.content)
    with xr.open_dataset(tmp_path / "r.nc") as ds:
        times = ds["time"].values
        assert 1 < len(frames) <= 3 < len(times)
        t_last, path_last = frames[-1]
        assert t_last == pytest.approx(float(times[-1]))
        mesh = meshio.read(path_last)
        np.testing.assert_allclose(mesh.points, ds["position"].values[-1], rtol=1e-6)
    assert client.get(f"/v1/ui/jobs/{job['id']}/paraview").status_code == 401


def test_package_data_ships_every_static_file():
    """A wheel holds what pyproject's package-data names: every file of the dashboard."""
    from pathlib import Path

    tomllib = pytest.importorskip("tomllib")   # Python 3.11+

    root = Path(__file__).resolve().parents[2]
    patterns = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"]["service.dashboard"]
    package = STATIC_DIR.parent
    shipped = {p for pattern in patterns for p in package.glob(pattern) if p.is_file()}
    files = {p for p in STATIC_DIR.rglob("*") if p.is_file()}
    assert files and files <= shipped, sorted(str(p) for p in files - shipped)


# --------------------------------------------------------------------------- continuation jobs

FORCE = "boundary.end.translation.2.force"


@pytest.fixture(scope="module")
def branch_job(client, settings):
    """A finished continuation job: the 20-segment Euler column (cases/euler-column.yaml)
    followed past its first branch point onto the buckled column (--switch)."""
    from solver.case import parse_text
    from svc_support import REPO

    path = REPO / "cases" / "euler-column.yaml"
    case = parse_text(path.read_bytes(), path.suffix, str(path))
    case["numerics"]["n_segments"] = 20
    body = {"case": case, "continuation": {"parameter": FORCE, "to": -0.4, "switch": True,
                                           "max_points": 60}}
    job = client.post("/v1/continuations", json=body, headers=AUTH).json()
    assert _run(settings, job["id"]) == "successful"
    return job["id"]


def test_a_continuation_jobs_branch_for_its_page(client, branch_job):
    """GET /v1/ui/jobs/{id}/branch: the parameter with its unit, the measures with round-off
    as zero (the planar elastica's end moment and writhe: constant zero), the branch point
    with the mode counts on either side, the switch, the stored shapes; the run's events
    route answers 409 for a branch, and the branch route 409 for a run."""
    answer = client.get(f"/v1/ui/jobs/{branch_job}/branch", headers=AUTH)
    assert answer.status_code == 200, answer.text
    view = answer.json()
    assert view["parameter"]["path"] == FORCE and view["parameter"]["unit"] == "N"
    assert view["parameter"]["label"] == f"{FORCE} (N)"
    n = view["n_points"]
    assert len(view["unstable_modes"]) == len(view["branch"]) == n and view["stored"] == list(range(n))
    assert view["switched_at"] is not None and max(view["branch"]) == 1
    first = view["events"][0]
    assert first["kind"] == "branch_point" and not first["simple"]        # a round column: a pair
    assert (first["modes_before"], first["modes_after"]) == (0, 2) and first["switched_here"]
    by_name = {m["name"]: m for m in view["measures"]}
    assert by_name["writhe"]["constant"] and set(by_name["writhe"]["values"]) == {0.0}
    assert by_name["end_moment_axial"]["constant"]
    assert not by_name["excursion"]["constant"] and max(by_name["excursion"]["values"]) > 0.1
    assert all(m["units"] for m in view["measures"])
    events = client.get(f"/v1/ui/jobs/{branch_job}/events", headers=AUTH)
    assert events.status_code == 409 and events.json()["type"].endswith("result-is-a-branch")
    assert f"/v1/ui/jobs/{branch_job}/branch" in events.json()["detail"]
    assert client.get(f"/v1/ui/jobs/{branch_job}/branch").status_code == 401
    assert client.get("/v1/ui/jobs/nope/branch", headers=AUTH).status_code == 404
    # one point's shape, as the page fetches it
    shape = client.get(f"/v1/jobs/{branch_job}/results/variables/position",
                       params={"point": str(n - 1)}, headers=AUTH).json()
    assert shape["dims"] == ["node", "xyz"] and len(shape["data"]) == 21


def test_a_runs_result_is_not_a_branch(client, settings):
    job = client.post("/v1/jobs", json=tiny_case("not a branch"), headers=AUTH).json()
    assert client.get(f"/v1/ui/jobs/{job['id']}/branch", headers=AUTH).status_code == 404
    _run(settings, job["id"])
    answer = client.get(f"/v1/ui/jobs/{job['id']}/branch", headers=AUTH)
    assert answer.status_code == 409 and answer.json()["type"].endswith("result-is-a-run")


def test_paraview_download_of_a_branch_is_its_shapes(client, branch_job, tmp_path, monkeypatch):
    """A continuation job's ParaView download (a 409, before that a 500): its stored shapes
    as a series over its points, at most PARAVIEW_MAX_FRAMES of them, the last one kept."""
    import io
    import zipfile

    import meshio
    import numpy as np
    import xarray as xr

    import service.dashboard as dashboard
    from service.export import read_pvd

    monkeypatch.setattr(dashboard, "PARAVIEW_MAX_FRAMES", 5)
    answer = client.get(f"/v1/ui/jobs/{branch_job}/paraview", headers=AUTH)
    assert answer.status_code == 200, answer.text
    zipfile.ZipFile(io.BytesIO(answer.content)).extractall(tmp_path)
    frames = read_pvd(tmp_path / f"{branch_job}.pvd")
    (tmp_path / "b.nc").write_bytes(client.get(f"/v1/jobs/{branch_job}/results",
                                               headers=AUTH).content)
    with xr.open_dataset(tmp_path / "b.nc") as ds:
        n = ds.sizes["point"]
        assert 1 < len(frames) <= 5 and frames[-1][0] == n - 1
        mesh = meshio.read(frames[-1][1])
        np.testing.assert_allclose(mesh.points, ds["position"].values[-1], rtol=1e-6)
        assert mesh.point_data["parameter"][0] == pytest.approx(float(ds["parameter"][-1]))
        np.testing.assert_allclose(mesh.point_data["radius"], 0.0025)


def test_the_job_list_says_each_jobs_kind(client, settings, branch_job):
    """The jobs list's kind column: a run, a sweep's member (with the sweep's id), a
    continuation."""
    plain = client.post("/v1/jobs", json=tiny_case("a plain run", t_end=0.02),
                        headers=AUTH).json()
    sweep = client.post("/v1/sweeps", headers=AUTH, json={
        "base": tiny_case("kinds"),
        "parameters": {"boundary.start.rotation.2.angular_velocity": [0.3, 0.6]}}).json()
    listed = {j["id"]: j for j in client.get("/v1/ui/jobs", params={"page_size": 200},
                                             headers=AUTH).json()["jobs"]}
    assert listed[branch_job]["kind"] == "continuation" and listed[branch_job]["sweep_id"] is None
    assert listed[plain["id"]]["kind"] == "dynamic" and listed[plain["id"]]["sweep_id"] is None
    for member in sweep["members"]:
        assert listed[member["job_id"]]["sweep_id"] == sweep["id"]


def test_a_resubmitted_identical_case_is_the_old_job_marked_reused(client, settings, branch_job,
                                                                     monkeypatch):
    """The answer to a submission that created no job says so (``reused``, also in the
    Hockle-Reused header), through the Python client too, for a run and a continuation; a
    status read later is not an answer to a submission (``reused`` null there)."""
    from service.client import HockleClient

    monkeypatch.delenv("HOCKLE_API_KEY", raising=False)
    case = tiny_case("resubmitted", t_end=0.02)
    with HockleClient("http://testserver", api_key=KEY, transport=client._transport) as hc:
        first = hc.submit(case)
        assert first.reused is None
        _run(settings, first.id)
        again = hc.submit(case)
        assert again.id == first.id and again.reused == "identical_case"
        assert hc.get(first.id).reused is None
        spec = hc.spec(branch_job)
        branch = hc.submit_continuation(spec["case"], **{
            k: spec["continuation"][k] for k in ("parameter", "to", "switch", "max_points")})
        assert branch.id == branch_job and branch.reused == "identical_case"
