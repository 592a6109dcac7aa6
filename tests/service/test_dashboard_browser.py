"""The dashboard in a real headless browser (issue 44): Selenium driving Chromium against a real
API process, redis-server and a Celery worker, with API keys.

Skipped when selenium, chromium or chromedriver is missing (.ci/run installs Debian's
``chromium`` and ``chromium-driver``). With ``HOCKLE_UI_SCREENSHOTS=DIR`` the tests save a
screenshot of each page there (docs/figures/dashboard-*.png are made that way).
"""
from __future__ import annotations

import io
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from svc_support import long_case, make_stack, tiny_case, wait_until

pytestmark = pytest.mark.service

KEY = "browser-key-0123456789abcdef"
XSS_NAME = '<script>window.__xss=1</script><img src=x onerror="window.__xss=2">'
WORKER_READY_S = 400     # a fresh worker compiles the numba kernels first on a loaded machine


def buckling_case(name: str, force: float = -10.0, angular_velocity: float = 0.0,
                  n_segments: int = 24) -> dict:
    """The tiny rod, clamped at both ends, pushed along its axis past its Euler load (4 pi^2
    EI / L^2 = 3.9 N) and twisted, with a small sideways load that starts the buckling:
    buckles within 1 s (onset 0.6-0.9 s for 6-10 N), ~1 s of solve."""
    case = tiny_case(name, n_segments=n_segments, dt=0.01, t_end=1.0)
    case["boundary"]["end"]["translation"][2] = {"force": force}
    case["boundary"]["start"]["rotation"][2] = {"angular_velocity": angular_velocity}
    case["distributed_forces"] = [{"value": [1e-3, 0.0, 0.0], "start": 0.0, "end": 0.2}]
    return case


def _browser_paths() -> tuple[str, str]:
    pytest.importorskip("selenium")
    binary = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")
                   if shutil.which(n)), None)
    driver = shutil.which("chromedriver")
    if binary is None or driver is None:
        pytest.skip("no chromium and chromedriver on PATH (apt-get install chromium chromium-driver)")
    return binary, driver


@pytest.fixture(scope="module")
def browser():
    binary, driver_path = _browser_paths()
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--window-size=1400,1500", "--force-device-scale-factor=1",
                "--disable-background-networking", "--disable-component-update"):
        options.add_argument(arg)
    options.binary_location = binary
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(driver_path))
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def stack(tmp_path_factory, redis_server):
    _browser_paths()
    s = make_stack(tmp_path_factory, "ui", {"HOCKLE_BROKER_URL": redis_server.url,
                                            "HOCKLE_API_KEYS": KEY})
    s.http.headers["Authorization"] = f"Bearer {KEY}"
    s.start_api(timeout=120)
    yield s
    s.close()


def _ensure_worker(stack) -> None:
    if "w1" not in stack.workers:
        stack.start_worker("w1", wait=False)
    wait_until(lambda: stack._ready("w1"), WORKER_READY_S, 0.5, "worker w1")


def _wait(driver, predicate, timeout=30, what="condition"):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(driver, timeout, poll_frequency=0.2).until(
        lambda d: predicate(d), message=f"timed out waiting for {what}")


def _open(driver, stack, fragment: str, key: str | None = KEY) -> None:
    """Load /ui/ fresh (a new page: the key typed again when given) and go to ``fragment``."""
    from selenium.webdriver.common.by import By

    driver.get(f"{stack.url}/ui/#{fragment}")
    driver.execute_script("sessionStorage.clear()")
    driver.refresh()
    login = _wait(driver, lambda d: d.find_element(By.ID, "login"), what="the page")
    _wait(driver, lambda d: login.is_displayed(), what="the key form")
    if key is not None:
        driver.find_element(By.ID, "key").send_keys(key)
        driver.find_element(By.CSS_SELECTOR, "#login-form button").click()
        _wait(driver, lambda d: not login.is_displayed(), what="the key to be accepted")


def _element(driver, element_id: str, timeout: float = 60):
    """The element with ``element_id`` once the page has made it: a job page builds its
    view (the 3-D canvas, the plots) only after its job's record has arrived."""
    from selenium.webdriver.common.by import By

    return _wait(driver, lambda d: d.find_elements(By.ID, element_id), timeout,
                 f"#{element_id}")[0]


def _shot(driver, name: str) -> None:
    target = os.environ.get("HOCKLE_UI_SCREENSHOTS")
    if target:
        Path(target).mkdir(parents=True, exist_ok=True)
        height = driver.execute_script("return document.documentElement.scrollHeight")
        driver.set_window_size(1400, max(900, min(int(height) + 20, 3000)))
        time.sleep(0.5)
        driver.save_screenshot(str(Path(target) / f"dashboard-{name}.png"))
        driver.set_window_size(1400, 1500)


def _paste(driver, area, text: str) -> None:
    """Put ``text`` in the textarea as a paste does (one input event)."""
    driver.execute_script("arguments[0].value = arguments[1];"
                          "arguments[0].dispatchEvent(new Event('input'))", area, text)


def _row_state(driver, job_id: str):
    """The job's row state, None while it is absent or being redrawn (the list's polling
    replaces rows between a lookup and the read: a stale element is "not yet")."""
    from selenium.common.exceptions import NoSuchElementException, StaleElementReferenceException
    from selenium.webdriver.common.by import By

    try:
        return driver.find_element(By.CSS_SELECTOR, f'tr[data-job-id="{job_id}"]').get_attribute(
            "data-state")
    except (NoSuchElementException, StaleElementReferenceException):
        return None


def _click(driver, selector: str, what: str) -> None:
    """Click the element at ``selector``, looked up again if a redraw replaced it."""
    from selenium.common.exceptions import NoSuchElementException, StaleElementReferenceException
    from selenium.webdriver.common.by import By

    def attempt(d):
        try:
            d.find_element(By.CSS_SELECTOR, selector).click()
            return True
        except (NoSuchElementException, StaleElementReferenceException):
            return False

    _wait(driver, attempt, 30, what)


def _successful_job(stack, case) -> str:
    _ensure_worker(stack)
    response = stack.submit(case, params={"fresh": "true"})
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]
    stack.wait_state(job_id, "successful", timeout=300)
    return job_id


def test_a_wrong_key_is_refused(browser, stack):
    from selenium.webdriver.common.by import By

    _open(browser, stack, "/jobs", key=None)
    _shot(browser, "login")
    browser.find_element(By.ID, "key").send_keys("not-a-key-of-this-service")
    browser.find_element(By.CSS_SELECTOR, "#login-form button").click()
    message = browser.find_element(By.ID, "login-message")
    _wait(browser, lambda d: "Refused" in message.text, what="the refusal")
    assert "401" in message.text
    assert browser.find_element(By.ID, "login").is_displayed()
    assert browser.find_elements(By.CSS_SELECTOR, "#main table") == []
    assert browser.execute_script("return sessionStorage.getItem('hockle.apiKey')") is None
    assert browser.execute_script("return window.localStorage.length") == 0


def test_submitted_job_goes_from_accepted_to_successful_in_the_list(browser, stack):
    from selenium.webdriver.common.by import By

    stack.stop_worker("w1")      # queued until a worker starts: the list must show accepted
    _open(browser, stack, "/submit")
    area = browser.find_element(By.ID, "case")
    yaml_text = ("schema_version: 1\nname: from the browser\n"
                 "rod: {length: 1.0, youngs_modulus: 1.25e7, shear_modulus: 5.0e6, "
                 "density: 1500.0, diameter: 0.02}\n"
                 "boundary:\n  start:\n"
                 "    translation: [{velocity: 0}, {velocity: 0}, {velocity: 0}]\n"
                 "    rotation: [{angular_velocity: 0}, {angular_velocity: 0}, "
                 "{angular_velocity: 1.0}]\n  end:\n"
                 "    translation: [{velocity: 0}, {velocity: 0}, {force: 0}]\n"
                 "    rotation: [{angular_velocity: 0}, {angular_velocity: 0}, "
                 "{angular_velocity: 0}]\n"
                 f"numerics: {{n_segments: 8, dt: 0.01, t_end: 0.05}}\n")
    # an invalid value first: the service's 422 is shown at its field, before submitting
    _paste(browser, area, yaml_text.replace("youngs_modulus: 1.25e7", "youngs_modulus: -5"))
    result = browser.find_element(By.ID, "check-result")
    _wait(browser, lambda d: result.get_attribute("data-state") == "invalid", what="the 422")
    errors = browser.find_elements(By.CSS_SELECTOR, ".fielderr")
    assert [e.get_attribute("data-loc") for e in errors] == ["rod.youngs_modulus"]
    assert "line 3" in errors[0].text and "youngs_modulus: -5" in errors[0].text
    _shot(browser, "submit")
    _paste(browser, area, yaml_text)
    _wait(browser, lambda d: result.get_attribute("data-state") == "valid", what="validation")
    browser.find_element(By.ID, "fresh").click()
    browser.find_element(By.ID, "submit").click()
    _wait(browser, lambda d: d.execute_script("return location.hash").startswith("#/job/"),
          what="the job page")
    job_id = browser.execute_script("return decodeURIComponent(location.hash.slice(6))")
    browser.get(f"{stack.url}/ui/#/jobs")
    _wait(browser, lambda d: _row_state(d, job_id) == "accepted", what="the job accepted")
    _ensure_worker(stack)
    _wait(browser, lambda d: _row_state(d, job_id) == "successful", 300, "the job successful")
    row = browser.find_element(By.CSS_SELECTOR, f'tr[data-job-id="{job_id}"]')
    assert "from the browser" in row.text and "100.0 %" in row.text
    assert row.find_element(By.CSS_SELECTOR, "td.kind").get_attribute("data-kind") == "run"
    _shot(browser, "jobs")


def test_job_page_draws_plots_and_the_rod(browser, stack):
    from PIL import Image
    from selenium.webdriver.common.by import By

    case = buckling_case("rod in 3-D", force=-10.0, angular_velocity=4.0)
    job_id = _successful_job(stack, case)
    _open(browser, stack, f"/job/{job_id}")
    plots = _element(browser, "plots")
    _wait(browser, lambda d: int(plots.get_attribute("data-count") or 0) >= 4, 60, "the plots")
    shown = {p.get_attribute("data-plot") for p in browser.find_elements(By.CSS_SELECTOR, ".plot")}
    assert {"energies", "topology", "dt", "newton"} <= shown
    assert len(browser.find_elements(By.CSS_SELECTOR, "#plots .plot canvas")) >= 4
    canvas = _element(browser, "rod3d")
    _wait(browser, lambda d: canvas.get_attribute("data-points"), 60, "the 3-D view")
    assert int(canvas.get_attribute("data-points")) == 25
    assert canvas.get_attribute("data-scale-bar").endswith(("m", "mm"))     # a length scale
    assert "youngs_modulus" in browser.find_element(By.ID, "case-yaml").text
    assert browser.find_elements(By.CSS_SELECTOR, "#events-table tr[data-event='buckling_onset']")
    # the onset named and explained as hockle run and hockle plot do (solver.results)
    assert browser.find_element(
        By.CSS_SELECTOR, "#events-table tr[data-event='buckling_onset'] td").text == "buckling onset"
    note = browser.find_element(By.CSS_SELECTOR, "#events p.muted").text
    assert "in the order they happened" in note
    assert "more than the rod's largest diameter across the line through its ends" in note
    # a non-blank drawing: many pixels off the background, in several shades
    pixels = np.asarray(Image.open(io.BytesIO(canvas.screenshot_as_png)).convert("RGB"),
                        dtype=int).reshape(-1, 3)
    colours, counts = np.unique(pixels, axis=0, return_counts=True)
    background = colours[np.argmax(counts)]
    drawn = int((np.abs(pixels - background).sum(axis=1) > 30).sum())
    assert drawn > 0.005 * len(pixels), (drawn, len(pixels))
    assert len(colours) > 20
    # the slider picks another output time: a new slice is fetched and drawn
    slider = browser.find_element(By.ID, "time-slider")
    browser.execute_script("arguments[0].value = 0; arguments[0].dispatchEvent(new Event('input'))",
                           slider)
    _wait(browser, lambda d: canvas.get_attribute("data-frame") == "0", 30, "frame 0")
    assert browser.find_element(By.ID, "time-label").text.startswith("t = 0 s")
    assert browser.find_element(By.ID, "download").is_displayed()
    browser.execute_script("arguments[0].value = arguments[0].max; "
                           "arguments[0].dispatchEvent(new Event('input'))", slider)
    _wait(browser, lambda d: canvas.get_attribute("data-frame") == slider.get_attribute("max"),
          30, "the last frame")
    _shot(browser, "job")


def test_job_page_draws_the_seabed_under_the_rod(browser, stack):
    """A case with a flat seabed: the 3-D view fetches the bottom (GET
    /v1/ui/jobs/{id}/seabed) and paints it under the rod, sand-coloured, with the rod still
    drawn over it; a case without a seabed draws none (the test above's rod)."""
    from PIL import Image
    from selenium.webdriver.common.by import By

    case = tiny_case("rod on the seabed", n_segments=12, dt=0.01, t_end=0.2)
    case["initial"] = {"tangent": [1.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}
    case["gravity"] = [0.0, 0.0, -9.81]
    case["seabed"] = {"elevation": -0.01}
    job_id = _successful_job(stack, case)
    _open(browser, stack, f"/job/{job_id}")
    canvas = _element(browser, "rod3d")
    _wait(browser, lambda d: int(canvas.get_attribute("data-seabed-quads") or 0) > 0, 60,
          "the seabed drawn")
    assert canvas.get_attribute("data-seabed") == "elevation"
    assert int(canvas.get_attribute("data-seabed-quads")) == 24 * 24
    assert "sea floor" in browser.find_element(By.ID, "view3d-info").text
    pixels = np.asarray(Image.open(io.BytesIO(canvas.screenshot_as_png)).convert("RGB"),
                        dtype=int).reshape(-1, 3)
    r, g, b = pixels.T
    sand = (r > g) & (g > b) & (r - b > 40)           # the bottom's colours
    blue = (b > r + 40)                                # the rod's
    assert sand.sum() > 0.02 * len(pixels), sand.sum()
    assert blue.sum() > 0.002 * len(pixels), blue.sum()
    _shot(browser, "job-seabed")


def test_a_successful_runs_warning_is_shown_on_its_page_and_in_the_list(browser, stack):
    """A run that completes with hockle_warning (the thin-rod plectoneme at 10x its step
    crosses the closure of an end's tangent; docs/numerics.md § 6) shows the warning on its
    page, under the state, and marks its row in the list and in a sweep's member table; a
    run without one shows neither (the buckling rod of the test above)."""
    from selenium.webdriver.common.by import By
    from rodcases import thin_plectoneme_case

    case = thin_plectoneme_case(0.2, 10.0).model_dump(mode="json")
    case["name"] = "warned plectoneme"
    warned = _successful_job(stack, case)
    plain = _successful_job(stack, buckling_case("no warning"))
    _open(browser, stack, f"/job/{warned}")
    _wait(browser, lambda d: d.find_elements(By.ID, "job-message"), 60, "the warning")
    note = browser.find_element(By.ID, "job-message")
    assert "warning" in note.get_attribute("class")
    assert note.text.startswith("Warning: ")
    assert "crossed the closure of the end tangents 1 time" in note.text
    _shot(browser, "job-warning")
    _open(browser, stack, f"/job/{plain}")
    _wait(browser, lambda d: d.find_element(By.ID, "job-head").get_attribute("data-state")
          == "successful", 60, "the plain job's state")
    assert browser.find_elements(By.ID, "job-message") == []
    _open(browser, stack, "/jobs")
    _wait(browser, lambda d: _row_state(d, warned) == "successful"
          and _row_state(d, plain) == "successful", 60, "both rows")
    row = browser.find_element(By.CSS_SELECTOR, f'tr[data-job-id="{warned}"]')
    marks = row.find_elements(By.CSS_SELECTOR, "[data-warning]")
    assert len(marks) == 1 and "closure" in marks[0].get_attribute("title")
    row = browser.find_element(By.CSS_SELECTOR, f'tr[data-job-id="{plain}"]')
    assert row.find_elements(By.CSS_SELECTOR, "[data-warning]") == []
    # a sweep's member table marks the warned member (Δt 0.2 s) and not the other (0.1 s)
    sweep = stack.http.post("/v1/sweeps", params={"fresh": "true"}, json={
        "base": case, "combine": "zip", "parameters": {"numerics.dt": [0.1, 0.2]}})
    assert sweep.status_code == 201, sweep.text
    sweep_id = sweep.json()["id"]
    wait_until(lambda: stack.http.get(f"/v1/sweeps/{sweep_id}").json()["state"]
               in ("successful", "failed", "dismissed"), 300, 0.5, "the sweep")
    _open(browser, stack, f"/sweep/{sweep_id}")
    _wait(browser, lambda d: len(d.find_elements(By.CSS_SELECTOR, "#members tbody tr")) == 2,
          60, "the members")
    rows = browser.find_elements(By.CSS_SELECTOR, "#members tbody tr")
    assert [r.get_attribute("data-state") for r in rows] == ["successful"] * 2
    assert rows[0].find_elements(By.CSS_SELECTOR, "[data-warning]") == []
    marks = rows[1].find_elements(By.CSS_SELECTOR, "[data-warning]")
    assert len(marks) == 1 and "closure" in marks[0].get_attribute("title")


def test_a_running_job_is_dismissed_from_the_list(browser, stack):
    from selenium.webdriver.common.by import By

    _ensure_worker(stack)
    job_id = stack.submit(long_case("to dismiss", t_end=60.0), params={"fresh": "true"}).json()["id"]
    _open(browser, stack, "/jobs")
    _wait(browser, lambda d: _row_state(d, job_id) == "running", 120, "the job running")
    _click(browser, f'button[data-dismiss="{job_id}"]', "the dismiss button")
    _wait(browser, lambda d: _row_state(d, job_id) == "dismissed", 60, "the job dismissed")
    assert "stopping" in browser.find_element(By.ID, "banner").text
    job = stack.job(job_id)
    assert job["reason"] == "cancelled_by_user" and job["progress"] < 100


def test_markup_in_a_case_name_is_shown_as_text(browser, stack):
    from selenium.webdriver.common.by import By

    job_id = stack.submit(tiny_case(XSS_NAME), params={"fresh": "true"}).json()["id"]
    _open(browser, stack, "/jobs")
    _wait(browser, lambda d: _row_state(d, job_id) is not None, what="the job's row")
    link = browser.find_element(By.CSS_SELECTOR, f'tr[data-job-id="{job_id}"] td.name a')
    assert link.text == XSS_NAME
    assert browser.find_elements(By.CSS_SELECTOR, "#jobs img, #jobs script") == []
    browser.get(f"{stack.url}/ui/#/job/{job_id}")
    heading = _wait(browser, lambda d: d.find_elements(By.ID, "job-name"), what="the job page")[0]
    assert heading.text == XSS_NAME
    assert browser.find_elements(By.CSS_SELECTOR, "main img, main script") == []
    time.sleep(1)
    assert browser.execute_script("return window.__xss === undefined")


def test_sweep_page_shows_members_and_the_threshold_map(browser, stack):
    from selenium.webdriver.common.by import By

    _ensure_worker(stack)
    base = buckling_case("sweep", n_segments=16)
    sweep = stack.http.post("/v1/sweeps", params={"fresh": "true"}, json={
        "base": base, "parameters": {
            "boundary.end.translation.2.force": [-4.0, -6.0, -10.0],
            "boundary.start.rotation.2.angular_velocity": [0.0, 4.0]}})
    assert sweep.status_code == 201, sweep.text
    sweep_id = sweep.json()["id"]
    final = wait_until(lambda: stack.http.get(f"/v1/sweeps/{sweep_id}").json()["state"]
                       in ("successful", "failed", "dismissed"), 300, 0.5, "the sweep")
    assert stack.http.get(f"/v1/sweeps/{sweep_id}").json()["state"] == "successful", final
    _open(browser, stack, f"/sweep/{sweep_id}")
    _wait(browser, lambda d: d.find_elements(By.ID, "map-canvas"), 60, "the map")
    rows = browser.find_elements(By.CSS_SELECTOR, "#members tbody tr")
    assert [r.get_attribute("data-state") for r in rows] == ["successful"] * 6
    # the members that buckled are coloured cells (6 and 10 N are past the Euler load, 3.9 N)
    assert int(browser.find_element(By.ID, "sweep-map").get_attribute("data-members")) >= 4
    _shot(browser, "sweep")
    # in the job list, each member's kind links to its sweep
    member = stack.http.get(f"/v1/sweeps/{sweep_id}").json()["members"][0]["job_id"]
    _open(browser, stack, "/jobs")
    _wait(browser, lambda d: _row_state(d, member) is not None, 60, "a member's row")
    kind = browser.find_element(By.CSS_SELECTOR, f'tr[data-job-id="{member}"] td.kind a')
    assert kind.text == "sweep member" and kind.get_attribute("href").endswith(f"#/sweep/{sweep_id}")


FORCE = "boundary.end.translation.2.force"


def _column(n_segments: int = 20) -> dict:
    """cases/euler-column.yaml at ``n_segments``: a round column, first branch point (a pair
    of modes) at 4π² EJ / L² = 0.24 N."""
    from solver.case import parse_text
    from svc_support import REPO

    path = REPO / "cases" / "euler-column.yaml"
    case = parse_text(path.read_bytes(), path.suffix, str(path))
    case["numerics"]["n_segments"] = n_segments
    return case


def _pixels(element):
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(element.screenshot_as_png)).convert("RGB"),
                      dtype=int).reshape(-1, 3)


def test_a_continuation_jobs_page_draws_its_branch(browser, stack):
    """A finished continuation job (the Euler column switched onto its buckled branch at
    the branch point): its page draws the bifurcation diagram (stable parts blue, unstable
    dashed red, the branch point marked), the 3-D shape of the chosen equilibrium with a
    length scale, the branch's events with the mode counts; a click on the diagram or the
    slider shows another point's shape; none of a run's widgets (time slider, scalar series,
    "simulated ... s") and no error box; the list calls it a continuation."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    _ensure_worker(stack)
    response = stack.http.post("/v1/continuations", params={"fresh": "true"}, json={
        "case": _column(), "continuation": {"parameter": FORCE, "to": -0.4, "switch": True,
                                             "max_points": 60}})
    assert response.status_code == 201, response.text
    job_id = response.json()["id"]
    stack.wait_state(job_id, "successful", timeout=300)
    n_points = stack.job(job_id)["step"]

    _open(browser, stack, f"/job/{job_id}")
    diagram = _wait(browser, lambda d: d.find_elements(By.ID, "branch-diagram"), 60,
                    "the diagram")[0]
    _wait(browser, lambda d: int(diagram.get_attribute("data-segments") or 0) > 0, 60,
          "the diagram drawn")
    canvas = _element(browser, "rod3d")
    _wait(browser, lambda d: canvas.get_attribute("data-points"), 60, "the shape drawn")
    # the diagram: a segment between each pair of points of one part, the branch point
    # marked, every point with a stored shape drawn (and clickable); lateral excursion
    assert int(diagram.get_attribute("data-segments")) >= n_points - 2
    assert int(diagram.get_attribute("data-events")) >= 1
    assert int(diagram.get_attribute("data-points")) == n_points
    assert diagram.get_attribute("data-measure") == "excursion"
    pixels = _pixels(diagram)
    r, g, b = pixels.T
    blue = (b > 150) & (r < 80) & (g < 140)                        # stable: #1f5fa8
    red = (r > 150) & (g < 90) & (b < 90)                          # unstable: #c0392b
    assert blue.sum() > 200 and red.sum() > 30, (blue.sum(), red.sum())
    # the shape: the last point (the buckled column), tube pixels in many shades
    assert canvas.get_attribute("data-frame") == str(n_points - 1)
    assert int(canvas.get_attribute("data-points")) == 21
    assert canvas.get_attribute("data-scale-bar").endswith(("m", "mm"))
    shades = _pixels(canvas)
    colours, counts = np.unique(shades, axis=0, return_counts=True)
    drawn = int((np.abs(shades - colours[np.argmax(counts)]).sum(axis=1) > 30).sum())
    assert drawn > 0.005 * len(shades) and len(colours) > 20, (drawn, len(colours))
    # events of the branch with the mode counts, and the labels with the unit
    rows = browser.find_elements(By.CSS_SELECTOR, "#branch-events-table tbody tr")
    kinds = [row.get_attribute("data-event") for row in rows]
    assert kinds[0] == "start" and kinds[-1] == "end" and "branch_point" in kinds
    bp = rows[kinds.index("branch_point")].text
    assert "pair" in bp and "0 → 2" in bp and "switched here" in bp
    assert f"{FORCE} (N)" in browser.find_element(By.ID, "branch-events-table").get_attribute(
        "textContent")
    assert "unstable modes along the branch" in browser.find_element(By.ID, "branch-modes").text
    assert "N" in browser.find_element(By.ID, "point-label").text
    # another point: the slider's first stored point, then a click on the diagram's left part
    slider = browser.find_element(By.ID, "point-slider")
    browser.execute_script("arguments[0].value = 0; arguments[0].dispatchEvent(new Event('input'))",
                           slider)
    _wait(browser, lambda d: canvas.get_attribute("data-frame") == "0", 30, "point 0")
    ActionChains(browser).move_to_element_with_offset(
        diagram, -diagram.size["width"] // 2 + 100, 0).click().perform()
    _wait(browser, lambda d: canvas.get_attribute("data-frame") != "0", 30, "a clicked point")
    # no widget of a run, no error
    page = browser.find_element(By.ID, "main").text
    assert "simulated" not in page and "did not happen" not in page
    assert browser.find_elements(By.ID, "time-slider") == []
    assert browser.find_elements(By.ID, "plots") == []
    assert browser.find_elements(By.CSS_SELECTOR, "#main .error") == []
    assert browser.find_element(By.ID, "download-paraview").is_displayed()
    assert stack.http.get(f"/v1/ui/jobs/{job_id}/paraview").status_code == 200
    browser.execute_script("arguments[0].value = arguments[0].max; "
                           "arguments[0].dispatchEvent(new Event('input'))", slider)
    _wait(browser, lambda d: canvas.get_attribute("data-frame") == str(n_points - 1), 30,
          "the last point")
    _shot(browser, "branch")
    _open(browser, stack, "/jobs")
    _wait(browser, lambda d: _row_state(d, job_id) == "successful", 60, "the row")
    kind = browser.find_element(By.CSS_SELECTOR, f'tr[data-job-id="{job_id}"] td.kind')
    assert kind.get_attribute("data-kind") == "continuation" and kind.text == "continuation"


def test_no_resource_from_another_origin(browser, stack):
    """Every request the pages made (the performance log of the whole session) went to this
    service; and the CSP really blocks another origin (a fetch the test injects is refused)."""
    from selenium.webdriver.common.by import By

    job_id = _successful_job(stack, tiny_case("origin"))
    browser.get_log("performance")     # start afresh
    for fragment in ("/jobs", f"/job/{job_id}", "/submit", "/sweeps"):
        _open(browser, stack, fragment)
        time.sleep(0.7)
    _wait(browser, lambda d: d.find_elements(By.ID, "job-name") or True, what="pages")
    urls = []
    for entry in browser.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
    assert any(u.endswith("/ui/app.js") for u in urls) and any("/v1/" in u for u in urls)
    foreign = [u for u in urls if not (u.startswith(stack.url + "/") or u.startswith(("data:", "blob:")))]
    assert foreign == [], foreign
    blocked = browser.execute_async_script(
        "var done = arguments[0];"
        "fetch('http://127.0.0.2:9/x').then(function () { done('loaded'); },"
        " function (e) { done('blocked: ' + e); });")
    assert blocked.startswith("blocked")
    logs = " ".join(e["message"] for e in browser.get_log("browser"))
    assert "Content Security Policy" in logs


def test_without_keys_the_page_says_so(browser, tmp_path_factory, redis_server):
    from selenium.webdriver.common.by import By

    _browser_paths()
    open_stack = make_stack(tmp_path_factory, "ui-open", {"HOCKLE_BROKER_URL": redis_server.url})
    try:
        open_stack.start_api(timeout=120)
        browser.get(f"{open_stack.url}/ui/#/jobs")
        browser.refresh()
        banner = browser.find_element(By.ID, "banner")
        _wait(browser, lambda d: "no API keys configured" in banner.text, what="the banner")
        # what the log prints, and when: only on a bind beyond loopback (service/serve.py)
        assert "NO AUTHENTICATION" in banner.text and "loopback" in banner.text
        _wait(browser, lambda d: d.find_elements(By.ID, "jobs"), what="the job list")
        assert not browser.find_element(By.ID, "login").is_displayed()
        assert browser.find_element(By.ID, "who").text == "no API keys configured"
    finally:
        open_stack.close()
