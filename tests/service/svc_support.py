"""Support of the service tests (fixtures are re-exported by conftest.py): a real redis-server on a free port, a fresh PostgreSQL database
on this machine's server, and real API and Celery worker processes.

The heavy fixtures are module-scoped: a test module starts its stack once and its tests run
against it in order (they are written so that each one also passes alone).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path

import httpx
import pytest

from rodcases import tiny_spec

REPO = Path(__file__).resolve().parents[2]

def tiny_case(name: str = "tiny", **numerics) -> dict:
    """The tests' tiny case (rodcases.tiny_spec) named ``name``, ``numerics`` over its own."""
    case = tiny_spec(name)
    case["numerics"].update(numerics)
    return case



@pytest.fixture(scope="module")
def settings(request, tmp_path_factory):
    """The in-process service's settings of a test module: a fresh data directory (SQLite
    registry and result store), the in-memory broker, progress at every step, and the
    module's ``SERVICE_SETTINGS`` (a dict of :class:`service.settings.Settings` fields,
    e.g. API keys) over these."""
    from service.settings import Settings

    fields = {"broker_url": "memory://", "progress_interval": 0.0,
              **getattr(request.module, "SERVICE_SETTINGS", {})}
    name = request.module.__name__.rpartition(".")[2]
    return Settings(data_dir=tmp_path_factory.mktemp(name), **fields)


@pytest.fixture(scope="module")
def client(request, settings):
    """The service's API in-process on ``settings`` (FastAPI's TestClient, the app's
    lifespan run): the one client of the in-process service tests. A module's
    ``RAISE_SERVER_EXCEPTIONS = False`` has a server error answered as a 500 instead of
    raised."""
    from fastapi.testclient import TestClient

    from service.app import create_app

    raising = getattr(request.module, "RAISE_SERVER_EXCEPTIONS", True)
    with TestClient(create_app(settings), raise_server_exceptions=raising) as c:
        yield c

def long_case(name: str = "long", t_end: float = 20.0) -> dict:
    """A case that runs for several seconds (n_segments 400, 2000 steps: ~5 s alone here)."""
    case = tiny_case(name, n_segments=400, t_end=t_end)
    case["output"] = {"every": 10}
    return case


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_until(predicate, timeout: float, interval: float = 0.1, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(interval)


def _stop(proc: subprocess.Popen, sig=signal.SIGTERM, timeout: float = 20.0) -> None:
    """Stop a process we started (and its process group: pool children)."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        return
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


# --- redis ---------------------------------------------------------------------------------------
class RedisServer:
    def __init__(self, directory: Path):
        self.dir = directory
        self.port = free_port()
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        log = open(self.dir / "redis.log", "a")
        self.proc = subprocess.Popen(
            ["redis-server", "--port", str(self.port), "--bind", "127.0.0.1", "--dir", str(self.dir),
             "--appendonly", "yes", "--appendfsync", "everysec", "--save", "",
             "--maxmemory-policy", "noeviction"],
            stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
        )
        import redis

        client = redis.Redis(port=self.port)
        wait_until(lambda: _ping(client), 15, what="redis-server")

    def stop(self) -> None:
        """SIGTERM: redis flushes the AOF and exits."""
        if self.proc is not None:
            _stop(self.proc)
            self.proc = None

    def restart(self) -> None:
        self.stop()
        self.start()


def _ping(client) -> bool:
    try:
        return bool(client.ping())
    except Exception:  # noqa: BLE001
        return False


@pytest.fixture(scope="module")
def redis_server(tmp_path_factory):
    if shutil.which("redis-server") is None:
        pytest.skip("redis-server is not on PATH")
    server = RedisServer(tmp_path_factory.mktemp("redis"))
    server.start()
    yield server
    server.stop()


# --- postgresql ----------------------------------------------------------------------------------
PG_ADMIN = "postgresql://postgres@127.0.0.1:5432/postgres"


@contextlib.contextmanager
def _fresh_pg_database(prefix: str):
    """A new PostgreSQL database ``<prefix>_<random>`` on the local server (its name is
    yielded), its connections ended and the database dropped on exit; skips the test when no
    server answers on 127.0.0.1:5432."""
    psycopg = pytest.importorskip("psycopg")
    try:
        admin = psycopg.connect(PG_ADMIN, autocommit=True, connect_timeout=3)
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no PostgreSQL server answers on 127.0.0.1:5432 ({exc})")
    name = f"{prefix}_{uuid.uuid4().hex[:10]}"
    admin.execute(f'CREATE DATABASE "{name}"')
    try:
        yield name
    finally:
        admin.execute(
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = %s", (name,))
        admin.execute(f'DROP DATABASE IF EXISTS "{name}"')
        admin.close()


@contextlib.contextmanager
def empty_database_url(kind: str, directory: Path, prefix: str):
    """The URL of an empty registry database: a SQLite file in ``directory``, or (kind
    "postgresql") a new PostgreSQL database ``<prefix>_<random>`` of its own, dropped on exit;
    skips the test when no server answers on 127.0.0.1:5432."""
    if kind == "sqlite":
        yield f"sqlite:///{directory / (prefix + '.db')}"
        return
    with _fresh_pg_database(prefix) as name:
        yield f"postgresql+psycopg://postgres@127.0.0.1:5432/{name}"


@pytest.fixture(scope="session")
def pg_url():
    """A fresh database hockle_test_<random> on the local server, dropped afterwards."""
    with _fresh_pg_database("hockle_test") as name:
        yield f"postgresql://postgres@127.0.0.1:5432/{name}"


# --- API and worker processes -----------------------------------------------------------------
class Stack:
    """An API process and any number of worker processes sharing one configuration."""

    def __init__(self, root: Path, env: dict[str, str]):
        self.root = root
        self.port = free_port()
        self.env = dict(os.environ)
        for var in list(self.env):
            if var.startswith("HOCKLE_"):
                del self.env[var]
        self.env.update({
            "HOCKLE_DATA_DIR": str(root / "data"),
            "HOCKLE_HOST": "127.0.0.1",
            "HOCKLE_PORT": str(self.port),
            "HOCKLE_PROGRESS_INTERVAL": "0.2",
            "HOCKLE_HEARTBEAT_INTERVAL": "1",
            "HOCKLE_LOG_LEVEL": "INFO",
            "PYTHONUNBUFFERED": "1",
        })
        self.env.update(env)
        self.api: subprocess.Popen | None = None
        self.workers: dict[str, subprocess.Popen] = {}
        self.http = httpx.Client(base_url=self.url, timeout=30)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def _spawn(self, args: list[str], log_name: str) -> subprocess.Popen:
        log = open(self.root / log_name, "a")
        return subprocess.Popen([sys.executable, *args], cwd=self.root, env=self.env, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)

    def start_api(self, timeout: float = 30) -> None:
        self.api = self._spawn(["-m", "service"], "api.log")
        wait_until(self._api_up, timeout, 0.2, "the API")

    def _api_up(self) -> bool:
        if self.api is not None and self.api.poll() is not None:
            raise AssertionError(f"the API exited: {self.log('api.log')[-3000:]}")
        try:
            return self.http.get("/v1/health", params={"live": "true"}).status_code == 200
        except httpx.TransportError:
            return False

    def stop_api(self) -> None:
        if self.api is not None:
            _stop(self.api)
            self.api = None

    def start_worker(self, name: str, wait: bool = True) -> subprocess.Popen:
        proc = self._spawn(["-m", "worker", "--concurrency", "1", "--hostname", f"{name}@test"],
                           f"worker-{name}.log")
        self.workers[name] = proc
        if wait:
            wait_until(lambda: self._ready(name), 60, 0.2, f"worker {name}")
        return proc

    def _ready(self, name: str) -> bool:
        proc = self.workers[name]
        if proc.poll() is not None:
            raise AssertionError(f"worker {name} exited: {self.log(f'worker-{name}.log')[-3000:]}")
        return f"{name}@test ready." in self.log(f"worker-{name}.log")

    def stop_worker(self, name: str, sig=signal.SIGTERM) -> None:
        proc = self.workers.pop(name, None)
        if proc is not None:
            _stop(proc, sig)

    def log(self, name: str) -> str:
        path = self.root / name
        return path.read_text(errors="replace") if path.exists() else ""

    def close(self) -> None:
        self.http.close()
        for name in list(self.workers):
            self.stop_worker(name)
        self.stop_api()

    # --- API helpers -------------------------------------------------------------------------
    def submit(self, case: dict, **kwargs) -> httpx.Response:
        return self.http.post("/v1/jobs", json=case, **kwargs)

    def job(self, job_id: str) -> dict:
        response = self.http.get(f"/v1/jobs/{job_id}")
        assert response.status_code == 200, response.text
        return response.json()

    def wait_state(self, job_id: str, states, timeout: float = 60) -> dict:
        states = (states,) if isinstance(states, str) else tuple(states)
        last = {}

        def check():
            last["job"] = self.job(job_id)
            return last["job"] if last["job"]["state"] in states else None

        try:
            return wait_until(check, timeout, 0.1, f"job {job_id} to be {states}")
        except AssertionError:
            raise AssertionError(f"job {job_id} is {last.get('job')}, not {states}") from None


def make_stack(tmp_path_factory, name: str, env: dict[str, str]) -> Stack:
    root = tmp_path_factory.mktemp(name)
    return Stack(root, env)


def settings_for(stack: Stack):
    """The Settings the stack's processes resolve from their environment."""
    from service.settings import Settings

    return Settings(**{k[len("HOCKLE_"):].lower(): v for k, v in stack.env.items()
                       if k.startswith("HOCKLE_")})


def registry_for(stack: Stack):
    """A Registry on the stack's database (to read events the API does not expose)."""
    from service.registry import Registry

    return Registry(settings_for(stack).registry_url)


def record_job(stack: Stack, case: dict):
    """Record an accepted job in the stack's registry as the API does, without sending its
    message (a message lost, or one the test sends itself). Returns the Job."""
    import solver
    from service.validation import validate_case

    settings = settings_for(stack)
    valid = validate_case(case, settings.max_case_size)
    limits = settings.time_limits(valid.grid_points, valid.n_steps, valid.contact is not None,
                                  t_end=float(valid.numerics.t_end))
    registry = registry_for(stack)
    try:
        job, _ = registry.create_job(
            spec_json=valid.canonical_json(), spec_hash=valid.spec_hash(),
            solver_version=solver.__version__, name=valid.name,
            grid_points=valid.grid_points, n_steps=valid.n_steps,
            t_end=float(valid.numerics.t_end), limits=limits)
    finally:
        registry.dispose()
    return job
