"""Settings of the service, its workers and its client, from ``HOCKLE_`` environment variables.

Every field below is one environment variable: ``HOCKLE_<FIELD NAME IN CAPITALS>``. The table in
``docs/service.md`` lists them all with their defaults; ``tests/service/test_deploy.py`` checks that
the table, ``docker-compose.yml`` and ``deploy/`` name only variables that exist here.

With nothing set, the service runs *embedded*: a SQLite registry and a SQLite-backed Celery broker
(kombu's SQLAlchemy transport) under ``HOCKLE_DATA_DIR``, so no server has to be installed.
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

from pydantic import Field, SecretStr, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "DatasetMetadata", "get_settings", "CONTACT_CALIBRATION_DT",
           "MIN_API_KEY_LENGTH"]

# The contact cost figures (docs/contact.md section 4) are per nominal step of the seed example,
# dt = 0.1 s; in contact the step control cuts the step to 1-25 ms whatever the nominal dt, so a
# contact case's cost is counted per 0.1 s of simulated time at least.
CONTACT_CALIBRATION_DT = 0.1

# an API key must be at least this long (a guessable key is no protection)
MIN_API_KEY_LENGTH = 16
# settings that child_env() does not hand to a worker process
SECRET_FIELDS = ("api_keys", "api_keys_file", "api_key")


class DatasetMetadata(BaseSettings):
    """Who makes the result files and on what terms: ACDD-1.3 global attributes.

    Each field is written into every result file (by ``hockle run`` and by the workers) as
    the ACDD attribute of the same name; unset ones keep the solver's defaults
    (:data:`solver.results.DEFAULT_METADATA`: ``naming_authority`` "hockle", ``creator_name``
    and ``license`` "not specified ...") or stay absent. Only strings, so a stray value never
    stops a run.
    """

    model_config = SettingsConfigDict(env_prefix="HOCKLE_", extra="ignore")

    naming_authority: str | None = Field(
        None, description="ACDD naming_authority of the result ids (job ids, case hashes), "
        "reverse-DNS recommended, e.g. org.example.rodlab; default hockle.")
    creator_name: str | None = Field(
        None, description="ACDD creator_name: the person or group who runs this installation.")
    creator_email: str | None = Field(None, description="ACDD creator_email.")
    creator_url: str | None = Field(None, description="ACDD creator_url.")
    creator_type: str | None = Field(
        None, description="ACDD creator_type: person, group, institution or position.")
    creator_institution: str | None = Field(None, description="ACDD creator_institution.")
    institution: str | None = Field(None, description="CF/ACDD institution.")
    publisher_name: str | None = Field(
        None, description="ACDD publisher_name: who serves the results.")
    publisher_email: str | None = Field(None, description="ACDD publisher_email.")
    publisher_url: str | None = Field(None, description="ACDD publisher_url.")
    publisher_type: str | None = Field(
        None, description="ACDD publisher_type: person, group, institution or position.")
    publisher_institution: str | None = Field(None, description="ACDD publisher_institution.")
    license: str | None = Field(
        None, description="ACDD license of the result files, e.g. CC-BY-4.0 or a URL.")
    project: str | None = Field(None, description="ACDD project.")
    program: str | None = Field(None, description="ACDD program.")
    acknowledgement: str | None = Field(None, description="ACDD acknowledgement.")
    contributor_name: str | None = Field(
        None, description="ACDD contributor_name (comma-separated for several).")
    contributor_role: str | None = Field(
        None, description="ACDD contributor_role, one per contributor_name.")

    def dataset_metadata(self) -> dict[str, str]:
        """The fields that are set, as ACDD attribute name -> value
        (for :func:`solver.results.apply_metadata`)."""
        return {name: getattr(self, name) for name in DatasetMetadata.model_fields
                if getattr(self, name)}


class Settings(DatasetMetadata):
    model_config = SettingsConfigDict(env_prefix="HOCKLE_", extra="ignore")

    # --- where things live -------------------------------------------------------------------
    data_dir: Path = Field(
        Path("hockle-data"),
        description="Directory for the embedded SQLite registry and broker files (made absolute).",
    )
    database_url: str | None = Field(
        None,
        description="SQLAlchemy URL of the job registry; default sqlite:///<data_dir>/registry.db. "
        "postgresql:// URLs use the psycopg 3 driver.",
    )
    broker_url: str | None = Field(
        None,
        description="Celery broker URL (redis://host:6379/0). Unset: embedded SQLite broker and a "
        "local worker started by `hockle serve`.",
    )
    results_dir: Path | None = Field(
        None,
        description="Result store: one NetCDF file per job id; default <data_dir>/results. A shared "
        "(ReadWriteMany) volume when workers run on several machines.",
    )
    queue: str = Field("hockle", description="Celery queue the jobs go to.")

    # --- HTTP ----------------------------------------------------------------------------------
    host: str = Field("127.0.0.1", description="Address `hockle serve` binds.")
    port: int = Field(8000, description="Port `hockle serve` binds.")
    public_url: str | None = Field(
        None, description="Base URL the client and `hockle submit` use; default http://<host>:<port>."
    )

    # --- access --------------------------------------------------------------------------------
    api_keys: SecretStr | None = Field(
        None,
        description="Comma-separated API keys. When set (or api_keys_file), every route but "
        "/v1/health and the docs needs `Authorization: Bearer <key>`, and each job belongs to "
        "the key that submitted it. Unset: no authentication (fit for 127.0.0.1 only).",
    )
    api_keys_file: Path | None = Field(
        None,
        description="File of API keys, one per line (blank lines and lines starting with # "
        "are skipped); read by the API at start-up, together with api_keys.",
    )
    api_key: SecretStr | None = Field(
        None,
        description="The key the client (HockleClient) and `hockle submit` send; not read by "
        "the API.",
    )
    allowed_hosts: str | None = Field(
        None,
        description="Without API keys: the host names (comma-separated, no port) the API "
        "answers in the Host header, so that a web page cannot reach it through a name of "
        "its own resolved to this machine (DNS rebinding); * answers any. Unset: localhost, "
        "127.0.0.1, ::1, the bind address HOCKLE_HOST (unless 0.0.0.0 or ::) and the host of "
        "HOCKLE_PUBLIC_URL. /v1/health and /metrics are not checked; nothing is with API "
        "keys, which are the protection then.",
    )
    rate_limit: float = Field(
        20.0, ge=0,
        description="Requests per second each API key may make, on average (a token bucket "
        "per key in each API process); 0 turns rate limiting off. Only with API keys.",
    )
    rate_limit_burst: int = Field(
        100, ge=1,
        description="Requests a key may make at once before rate_limit applies (the bucket's "
        "size).",
    )

    # --- limits --------------------------------------------------------------------------------
    max_case_size: int = Field(
        20_000_000,
        gt=0,
        description="Largest accepted case: grid points x time steps.",
    )
    max_slice_values: int = Field(
        1_000_000, gt=0, description="Largest variable slice served as JSON (number of values)."
    )
    body_parse_timeout: float = Field(
        2.0, gt=0,
        description="Seconds one request body (a case, a sweep, a continuation; JSON or YAML) "
        "may take to parse, on a thread of its own, before it is refused with 413; a case spec "
        "parses in milliseconds.",
    )

    # --- worker --------------------------------------------------------------------------------
    embedded_worker: bool = Field(
        True, description="`hockle serve` without a broker URL also starts a local worker process."
    )
    worker_concurrency: int = Field(1, ge=1, description="Solver processes per `hockle worker`.")
    blas_threads: int = Field(1, ge=1, description="BLAS/OpenMP threads per worker process.")
    worker_nice: int = Field(
        0, ge=0, le=19,
        description="Niceness added to worker processes, so that an API on the same machine "
        "stays responsive while they solve (`hockle serve` embedded uses 10 unless set).",
    )
    progress_interval: float = Field(
        1.0, ge=0, description="Least seconds between two progress writes to the registry."
    )
    cancel_check_interval: float = Field(
        0.0,
        ge=0,
        description="Least seconds between two reads of the cancel flag; 0 reads it before every "
        "time step.",
    )
    heartbeat_interval: float = Field(
        10.0, gt=0, description="Seconds between worker heartbeats (and reaper sweeps)."
    )
    worker_seen_window: float = Field(
        60.0, gt=0, description="A worker whose last heartbeat is older than this is not listed."
    )

    # --- failures: lost workers, lost messages, registry outages ------------------------------
    job_heartbeat_timeout: float = Field(
        60.0,
        gt=0,
        description="A running job whose registry heartbeat (written every heartbeat_interval by "
        "the process that solves it) is older than this has lost its worker: it is queued again "
        "(attempt + 1), or failed after max_attempts.",
    )
    max_attempts: int = Field(
        3,
        ge=1,
        description="Most attempts (claims by a worker) of one job; a job whose worker is lost on "
        "its last attempt fails with reason internal_error.",
    )
    checkpoint_interval: float = Field(
        30.0,
        ge=0,
        description="Wall-clock seconds between checkpoints of a running job in the result store "
        "(<id>.ckpt; also written after the first step in contact and when the worker stops a "
        "solve); a re-run after a lost worker continues from the last one instead of from "
        "t = 0. 0 turns checkpoints off.",
    )
    checkpoint_progress: float = Field(
        0.1,
        ge=0,
        le=1,
        description="A checkpoint is also written when the simulated time has advanced this "
        "fraction of t_end since the last one (whichever of this and checkpoint_interval "
        "comes first); 0: by wall time only.",
    )
    requeue_after: float = Field(
        300.0,
        gt=0,
        description="An accepted job not claimed by any worker this long after it was queued is "
        "queued again (its message may be lost); the wait doubles with each re-queue, to 1 h.",
    )
    registry_retry_timeout: float = Field(
        300.0,
        ge=0,
        description="How long a worker retries (with backoff) a registry that is locked or "
        "unreachable when it claims or finishes a job, before it hands the message back to the "
        "broker.",
    )
    registry_busy_timeout: float = Field(
        30.0,
        gt=0,
        description="SQLite registry: seconds a statement waits for another connection's lock "
        "before it fails with 'database is locked' (then retried as above).",
    )
    registry_request_timeout: float = Field(
        5.0,
        gt=0,
        description="API: seconds one request waits on the registry (a PostgreSQL statement "
        "or lock, a connection from the pool, a SQLite lock, a connection to the server) "
        "before it answers 503 registry-unavailable with Retry-After; well below the clients' "
        "and the probes' time-outs. Workers wait longer (registry_busy_timeout, "
        "registry_retry_timeout).",
    )
    auto_migrate: bool = Field(
        True,
        description="At start-up the API and each worker bring the registry's schema to the "
        "code's (Alembic `upgrade head`, under a lock; a no-op when it is there). False: they "
        "only check it and refuse to start until an operator runs `hockle db upgrade`.",
    )

    # --- time limits (seconds) -----------------------------------------------------------------
    time_limit_base: float = Field(60.0, gt=0, description="Hard time limit of the smallest job.")
    time_limit_per_unit: float = Field(
        2.0e-4,
        ge=0,
        description="Hard time limit added per grid point x time step.",
    )
    time_limit_per_unit_contact: float = Field(
        5.6e-3,
        ge=0,
        description="The same for cases with self-contact, counted over max(time steps, "
        "t_end / 0.1 s) because contact sets its own sub-steps: the largest measured contact "
        "cost, 2.8e-3 s per grid point per 0.1 s of simulated time (docs/contact.md section 4), "
        "times 2 for the shared machine's load (docs/service.md, Time limits).",
    )
    time_limit_max: float = Field(
        6 * 3600.0, gt=0,
        description="Cap of the hard time limit, derived or requested (POST /v1/jobs?time_limit=).",
    )
    soft_limit_fraction: float = Field(
        0.95, gt=0, lt=1, description="Soft time limit as a fraction of the hard one."
    )
    budget_fraction: float = Field(
        0.9,
        gt=0,
        lt=1,
        description="Solver wall-clock budget as a fraction of the soft limit: the solver stops "
        "cleanly (partial dataset kept, reason timeout) before Celery has to interrupt it.",
    )
    reaper_grace: float = Field(
        30.0, ge=0, description="Seconds past a job's hard limit before the reaper fails it."
    )
    visibility_timeout: float | None = Field(
        None,
        description="Redis visibility timeout: an unacknowledged job is redelivered after this long "
        "(a worker died). Default time_limit_max + 600; must exceed time_limit_max.",
    )
    unacked_restore_interval: float = Field(
        10.0, gt=0, description="Seconds between a worker's sweeps for redeliverable jobs (Redis)."
    )

    log_level: str = Field("INFO", description="Log level of the API and the workers.")

    @model_validator(mode="after")
    def _derive(self) -> "Settings":
        self.data_dir = Path(os.path.abspath(os.path.expanduser(self.data_dir)))
        if self.results_dir is None:
            self.results_dir = self.data_dir / "results"
        self.results_dir = Path(os.path.abspath(os.path.expanduser(self.results_dir)))
        if self.visibility_timeout is None:
            self.visibility_timeout = self.time_limit_max + 600.0
        if self.visibility_timeout <= self.time_limit_max:
            raise ValueError(
                "HOCKLE_VISIBILITY_TIMEOUT must exceed HOCKLE_TIME_LIMIT_MAX, or a job still "
                "running would be delivered to a second worker"
            )
        if self.job_heartbeat_timeout < 2 * self.heartbeat_interval:
            raise ValueError(
                "HOCKLE_JOB_HEARTBEAT_TIMEOUT must be at least twice HOCKLE_HEARTBEAT_INTERVAL, "
                "or a live job between two heartbeats would be taken for a lost one"
            )
        return self

    # --- derived -------------------------------------------------------------------------------
    @property
    def embedded(self) -> bool:
        """True when no broker URL is configured (SQLite broker, local worker)."""
        return not self.broker_url

    @property
    def registry_url(self) -> str:
        url = self.database_url or f"sqlite:///{self.data_dir / 'registry.db'}"
        if url.startswith("postgresql://") or url.startswith("postgres://"):
            url = "postgresql+psycopg://" + url.split("://", 1)[1]
        return url

    @property
    def celery_broker_url(self) -> str:
        return self.broker_url or f"sqla+sqlite:///{self.data_dir / 'broker.db'}"

    @property
    def base_url(self) -> str:
        if self.public_url:
            return self.public_url.rstrip("/")
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        return f"http://{host}:{self.port}"

    def time_limits(self, grid_points: int, n_steps: int, contact: bool = False, *,
                    t_end: float | None = None,
                    requested: float | None = None) -> tuple[float, float, float]:
        """(hard, soft, solver budget) in seconds for a case of this size.

        The hard limit is ``requested`` when the job asked for one (the caller checks it against
        ``time_limit_max``), else ``time_limit_base`` plus the cost model: per grid point and
        time step, ``time_limit_per_unit``; with self-contact (``contact``),
        ``time_limit_per_unit_contact`` per grid point and per time step or per
        ``CONTACT_CALIBRATION_DT`` of simulated time (``t_end``), whichever are more, because
        the contact step control cuts the step to a few ms whatever the nominal dt. Both are
        capped at ``time_limit_max``. Soft = ``soft_limit_fraction`` x hard, budget =
        ``budget_fraction`` x soft.
        """
        if requested is not None:
            hard = min(self.time_limit_max, float(requested))
        else:
            hard = min(self.time_limit_max,
                       self.time_limit_base + self.predicted_cost(grid_points, n_steps, contact,
                                                                  t_end=t_end))
        soft = hard * self.soft_limit_fraction
        return hard, soft, soft * self.budget_fraction

    def predicted_cost(self, grid_points: int, n_steps: int, contact: bool = False, *,
                       t_end: float | None = None) -> float:
        """Upper estimate of a case's wall time in seconds (without ``time_limit_base``)."""
        if not contact:
            return self.time_limit_per_unit * grid_points * n_steps
        steps = float(n_steps)
        if t_end is not None:
            steps = max(steps, t_end / CONTACT_CALIBRATION_DT)
        return self.time_limit_per_unit_contact * grid_points * steps

    def allowed_host_names(self) -> frozenset[str] | None:
        """The Host names the API answers without API keys (:attr:`allowed_hosts`, or its
        default: the loopback names, the bind address and the public URL's host), lower
        case, IPv6 without brackets; None when any host is allowed (``*``)."""
        from urllib.parse import urlsplit

        if self.allowed_hosts is not None:
            names = {host_name(h) for h in self.allowed_hosts.split(",") if h.strip()}
            return None if "*" in names else frozenset(names)
        names = {"localhost", "127.0.0.1", "::1"}
        if self.host.strip() not in ("0.0.0.0", "::", "[::]", ""):
            names.add(host_name(self.host))
        if self.public_url:
            public = urlsplit(self.public_url).hostname
            if public:
                names.add(host_name(public))
        return frozenset(names)

    def load_api_keys(self) -> list[str]:
        """The API keys from ``api_keys`` and ``api_keys_file`` (empty: no authentication).

        Raises ``ValueError`` naming the variable and the key's place (never the key) for
        an unreadable file, an empty file, or a key that is too short or holds whitespace,
        commas or non-ASCII characters (a key travels in an HTTP header).
        """
        keys: list[tuple[str, str]] = []
        if self.api_keys is not None:
            raw = self.api_keys.get_secret_value()
            keys += [(f"HOCKLE_API_KEYS: key {n}", k) for n, k in
                     enumerate((k.strip() for k in raw.split(",") if k.strip()), 1)]
            if raw.strip() and not keys:
                raise ValueError("HOCKLE_API_KEYS: no key in it (comma-separated keys)")
        if self.api_keys_file is not None:
            path = Path(os.path.expanduser(self.api_keys_file))
            try:
                lines = path.read_text(encoding="utf-8").splitlines()
            except (OSError, UnicodeDecodeError) as exc:
                raise ValueError(f"HOCKLE_API_KEYS_FILE: cannot read {path}: "
                                 f"{getattr(exc, 'strerror', None) or exc}") from None
            from_file = [(f"HOCKLE_API_KEYS_FILE: the key on line {n} of {path}", line.strip())
                         for n, line in enumerate(lines, 1)
                         if line.strip() and not line.strip().startswith("#")]
            if not from_file:
                raise ValueError(f"HOCKLE_API_KEYS_FILE: {path} holds no key (one per line)")
            keys += from_file
        for where, key in keys:
            problem = None
            if len(key) < MIN_API_KEY_LENGTH:
                problem = f"is {len(key)} characters long; use at least {MIN_API_KEY_LENGTH}"
            elif not key.isascii() or any(c.isspace() or c == "," or not c.isprintable()
                                          for c in key):
                problem = "holds whitespace, a comma or a non-ASCII or control character"
            if problem:
                raise ValueError(
                    f"{where} {problem} (make one with: python3 -c "
                    f"'import secrets; print(secrets.token_urlsafe(32))')")
        return list(dict.fromkeys(key for _, key in keys))

    def child_env(self) -> dict[str, str]:
        """Environment that makes a child process resolve the same settings (the API keys and
        the client's key excepted: a worker never authenticates)."""
        env = {}
        for name, value in self.model_dump().items():
            if value is None or name in SECRET_FIELDS:
                continue
            env[f"HOCKLE_{name.upper()}"] = str(value)
        return env


def host_name(value: str) -> str:
    """The host of a Host header or a setting: lower case, without the port, the brackets
    of an IPv6 address or a trailing dot (``[::1]:8000`` -> ``::1``)."""
    value = value.strip().lower()
    if value.startswith("["):
        end = value.find("]")
        return value[1:end] if end > 0 else value
    if value.count(":") == 1:
        value = value.split(":", 1)[0]
    return value.rstrip(".")


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
