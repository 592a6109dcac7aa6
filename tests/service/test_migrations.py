"""Schema migrations of the job registry (service/migrations, Alembic), on SQLite and on
PostgreSQL (a database of its own; skipped when no server answers on 127.0.0.1:5432).

Fresh database -> upgrade head -> the models' tables, columns and indexes exist and the
registry works; a registry made before migrations (first-release tables with rows, or the
later ones without the owner column) -> upgrade head -> columns added, rows kept; upgrading
twice changes nothing; autogenerate finds no difference between the models and a registry
at head; concurrent upgrades; HOCKLE_AUTO_MIGRATE=false; the command line."""
from __future__ import annotations

import datetime as dt
import subprocess
import sys
from pathlib import Path

import pytest
import sqlalchemy as sa

from service import migrations
from service.registry import Base, Registry
from svc_support import empty_database_url

REPO = Path(__file__).resolve().parents[2]
T0 = dt.datetime(2026, 1, 1, 12, 0, 0)


@pytest.fixture(params=["sqlite", "postgresql"])
def url(request, tmp_path):
    """An empty registry database: a SQLite file, or a new PostgreSQL database of its own
    for this test (dropped afterwards)."""
    with empty_database_url(request.param, tmp_path, "hockle_mig") as db_url:
        yield db_url


def schema(url: str) -> dict[str, tuple[set[str], set[str]]]:
    """table -> (column names, index names) of hockle's tables at ``url``."""
    engine = sa.create_engine(url)
    try:
        inspector = sa.inspect(engine)
        return {name: ({c["name"] for c in inspector.get_columns(name)},
                       {ix["name"] for ix in inspector.get_indexes(name)})
                for name in inspector.get_table_names() if name.startswith("hockle_")}
    finally:
        engine.dispose()


def models() -> dict[str, tuple[set[str], set[str]]]:
    return {name: ({c.name for c in table.columns}, {ix.name for ix in table.indexes})
            for name, table in Base.metadata.tables.items()}


def run_a_job(reg: Registry) -> str:
    """create -> claim -> heartbeat -> finish one job; returns its id."""
    job, created = reg.create_job(
        spec_json="{}", spec_hash="h" * 64, solver_version="test", name="new", grid_points=11,
        n_steps=10, t_end=1.0, limits=(60.0, 50.0, 40.0), idempotency_key="k-1",
        request_fingerprint="f", owner="o" * 64)
    assert created and job.state == "accepted"
    attempt = reg.claim(job.id, "w1")
    assert attempt == 1
    assert reg.job_heartbeat(job.id, attempt)
    assert reg.finish(job.id, attempt, state="successful", result_path="x.nc", worker="w1")
    done = reg.get(job.id)
    assert done.state == "successful" and done.owner == "o" * 64 and done.dispatches == 1
    assert [e.kind for e in reg.events(job.id)][-1] == "finished"
    return job.id


# --- a new registry -----------------------------------------------------------------------------
def test_fresh_database_upgrade_head_makes_the_models_schema_and_the_registry_works(url):
    assert migrations.current(url) is None
    migrations.upgrade(url)
    assert migrations.current(url) == migrations.head()
    have = schema(url)
    assert set(have) == set(models()) | {migrations.VERSION_TABLE}
    for name, (columns, indexes) in models().items():
        assert have[name][0] == columns, name
        assert indexes <= have[name][1], name
    reg = Registry(url)
    try:
        run_a_job(reg)
        sweep = reg.create_sweep(name="s", combine="grid", parameters={"a.b": [1, 2]},
                                 job_ids=["j1", "j2"], base_json="{}", owner=None)
        assert reg.get_sweep(sweep.id).job_ids == ["j1", "j2"]
    finally:
        reg.dispose()


def test_upgrading_twice_changes_nothing(url):
    migrations.upgrade(url)
    before = schema(url)
    migrations.upgrade(url)
    reg = Registry(url)
    try:
        reg.create_schema(auto_migrate=True)  # what the API and workers do at start-up
        run_a_job(reg)
    finally:
        reg.dispose()
    assert schema(url) == before
    assert migrations.current(url) == migrations.head()


def test_the_migrations_build_what_the_models_define(url):
    """The `alembic check` of hockle: autogenerate finds no difference at head (a model
    changed without a revision fails here), and it would find one (the check is not blind)."""
    migrations.upgrade(url)
    assert migrations.check(url) == []
    migrations.downgrade(url, "0002_heartbeats_sweeps")  # no owner column or index
    diffs = migrations.check(url)
    assert {d[0] if isinstance(d, tuple) else d[0][0] for d in diffs} >= {"add_column"}
    assert any("owner" in repr(d) for d in diffs)
    migrations.upgrade(url)
    assert migrations.check(url) == []


# --- a registry made by an older hockle -------------------------------------------------------
def _first_release_tables(metadata: sa.MetaData, *, heartbeats: bool) -> None:
    """The tables as the hockle before migrations made them (create_all of its models);
    ``heartbeats``: as made after heartbeats and sweeps came (no jobs.owner)."""
    columns = [
        sa.Column("id", sa.String(36), primary_key=True),
        sa.Column("name", sa.String(200)),
        sa.Column("state", sa.String(16), nullable=False, index=True),
        sa.Column("reason", sa.String(32)),
        sa.Column("message", sa.Text),
        sa.Column("spec_json", sa.Text, nullable=False),
        sa.Column("spec_hash", sa.String(64), nullable=False, index=True),
        sa.Column("solver_version", sa.String(32), nullable=False),
        sa.Column("grid_points", sa.Integer, nullable=False),
        sa.Column("n_steps", sa.Integer, nullable=False),
        sa.Column("t_end", sa.Float, nullable=False),
        sa.Column("idempotency_key", sa.String(200), unique=True),
        sa.Column("request_fingerprint", sa.String(64)),
        sa.Column("created_at", sa.DateTime, nullable=False, index=True),
        sa.Column("updated_at", sa.DateTime, nullable=False),
        sa.Column("started_at", sa.DateTime),
        sa.Column("finished_at", sa.DateTime),
        sa.Column("deadline_at", sa.DateTime, index=True),
        sa.Column("progress", sa.Float, nullable=False),
        sa.Column("sim_time", sa.Float, nullable=False),
        sa.Column("step", sa.Integer, nullable=False),
        sa.Column("wall_time", sa.Float),
        sa.Column("eta_seconds", sa.Float),
        sa.Column("failed_time", sa.Float),
        sa.Column("failed_step", sa.Integer),
        sa.Column("worker", sa.String(200)),
        sa.Column("attempts", sa.Integer, nullable=False),
        sa.Column("cancel_requested", sa.Boolean, nullable=False),
        sa.Column("time_limit", sa.Float, nullable=False),
        sa.Column("soft_time_limit", sa.Float, nullable=False),
        sa.Column("wall_clock_budget", sa.Float, nullable=False),
        sa.Column("result_path", sa.Text),
        sa.Column("result_partial", sa.Boolean, nullable=False),
    ]
    if heartbeats:
        columns += [sa.Column("heartbeat_at", sa.DateTime), sa.Column("enqueued_at", sa.DateTime),
                    sa.Column("dispatches", sa.Integer)]
    sa.Table("hockle_jobs", metadata, *columns)
    sa.Table("hockle_job_events", metadata,
             sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
             sa.Column("job_id", sa.String(36), nullable=False, index=True),
             sa.Column("at", sa.DateTime, nullable=False),
             sa.Column("kind", sa.String(32), nullable=False),
             sa.Column("attempt", sa.Integer), sa.Column("worker", sa.String(200)),
             sa.Column("detail", sa.Text))
    sa.Table("hockle_workers", metadata,
             sa.Column("name", sa.String(200), primary_key=True),
             sa.Column("last_seen", sa.DateTime, nullable=False),
             sa.Column("current_job", sa.String(36)))
    if heartbeats:
        sa.Table("hockle_sweeps", metadata,
                 sa.Column("id", sa.String(36), primary_key=True),
                 sa.Column("name", sa.String(200)),
                 sa.Column("combine", sa.String(8), nullable=False),
                 sa.Column("parameters_json", sa.Text, nullable=False),
                 sa.Column("member_job_ids", sa.Text, nullable=False),
                 sa.Column("base_json", sa.Text, nullable=False),
                 sa.Column("owner", sa.String(64), index=True),
                 sa.Column("created_at", sa.DateTime, nullable=False, index=True),
                 sa.Column("dismissed_at", sa.DateTime))


def _old_job(job_id: str, state: str, **extra) -> dict:
    row = dict(id=job_id, name=f"old {job_id}", state=state, spec_json="{}", spec_hash="a" * 64,
               solver_version="0.0.9", grid_points=11, n_steps=10, t_end=1.0,
               idempotency_key=f"key-{job_id}", created_at=T0, updated_at=T0, progress=0.0,
               sim_time=0.0, step=0, attempts=0, cancel_requested=False, time_limit=60.0,
               soft_time_limit=50.0, wall_clock_budget=40.0, result_partial=False)
    row.update(extra)
    return row


@pytest.mark.parametrize("era", ["first-release", "heartbeats"])
def test_a_registry_made_before_migrations_is_adopted_with_its_rows(url, era):
    metadata = sa.MetaData()
    _first_release_tables(metadata, heartbeats=era == "heartbeats")
    engine = sa.create_engine(url)
    with engine.begin() as conn:
        metadata.create_all(conn)
        jobs = metadata.tables["hockle_jobs"]
        conn.execute(jobs.insert(), _old_job(
            "done", "successful", attempts=1, progress=100.0, sim_time=1.0, step=10,
            finished_at=T0, result_path="done.nc"))
        conn.execute(jobs.insert(), _old_job("queued", "accepted"))
        conn.execute(metadata.tables["hockle_job_events"].insert(), [
            dict(job_id="done", at=T0, kind="submitted"),
            dict(job_id="done", at=T0, kind="finished", attempt=1, worker="w0")])
        conn.execute(metadata.tables["hockle_workers"].insert(),
                     [dict(name="w0", last_seen=T0, current_job=None)])
    engine.dispose()
    assert "owner" not in schema(url)["hockle_jobs"][0]

    reg = Registry(url)
    try:
        reg.create_schema()  # start-up of a new hockle: HOCKLE_AUTO_MIGRATE is true by default
        assert migrations.current(url) == migrations.head()
        have = schema(url)
        for name, (columns, indexes) in models().items():
            assert have[name][0] == columns, name
            assert indexes <= have[name][1], name
        assert migrations.check(url) == []

        # the rows are kept, the new columns empty
        old = reg.get("done")
        assert (old.state, old.result_path, old.attempts, old.owner, old.heartbeat_at) == (
            "successful", "done.nc", 1, None, None)
        assert old.kind == "dynamic"        # 0004: every job recorded before is dynamic
        assert [e.kind for e in reg.events("done")] == ["submitted", "finished"]
        assert sorted(j.id for j in reg.list().jobs) == ["done", "queued"]
        assert reg.by_idempotency_key("key-done").id == "done"
        # an old accepted job is sent again by the sweeper (no enqueued_at: its created_at)
        assert [j.id for j in reg.requeue_unclaimed(after=60.0)] == ["queued"]
        assert reg.claim("queued", "w1") == 1
        assert reg.finish("queued", 1, state="successful", result_path="q.nc")
        run_a_job(reg)
        reg.create_schema()  # the next start-up: nothing to do
        assert schema(url) == have
    finally:
        reg.dispose()


# --- several processes, and operators ---------------------------------------------------------
def test_processes_starting_at_once_migrate_once(url):
    """Four processes upgrade a new registry at the same moment (an API and its workers
    starting together): all succeed (the advisory lock / the SQLite write lock) and the
    registry is at head once."""
    code = ("import sys; from service import migrations; migrations.upgrade(sys.argv[1]); "
            "print(migrations.current(sys.argv[1]))")
    procs = [subprocess.Popen([sys.executable, "-c", code, url], cwd=REPO, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE) for _ in range(4)]
    results = [p.communicate(timeout=120) for p in procs]
    for proc, (out, err) in zip(procs, results):
        assert proc.returncode == 0, err[-2000:]
        assert out.strip() == migrations.head()
    engine = sa.create_engine(url)
    try:
        with engine.connect() as conn:
            rows = conn.execute(sa.text(f"SELECT version_num FROM {migrations.VERSION_TABLE}"))
            assert [r[0] for r in rows] == [migrations.head()]
    finally:
        engine.dispose()
    assert migrations.check(url) == []


def test_without_auto_migrate_start_up_refuses_an_old_registry_and_says_what_to_run(url):
    reg = Registry(url)
    try:
        with pytest.raises(migrations.SchemaNotCurrent) as info:
            reg.create_schema(auto_migrate=False)
        message = str(info.value)
        assert "HOCKLE_AUTO_MIGRATE" in message and "hockle db upgrade" in message
        assert migrations.head() in message
        assert schema(url) == {}  # nothing was created
        migrations.upgrade(url, "0002_heartbeats_sweeps")
        with pytest.raises(migrations.SchemaNotCurrent, match="0002_heartbeats_sweeps"):
            reg.create_schema(auto_migrate=False)
        migrations.upgrade(url)
        reg.create_schema(auto_migrate=False)
        run_a_job(reg)
    finally:
        reg.dispose()


def test_auto_migrate_setting_reaches_the_api(tmp_path, monkeypatch):
    from service.app import create_app
    from service.settings import Settings

    settings = Settings(data_dir=tmp_path / "data", auto_migrate=False)
    with pytest.raises(migrations.SchemaNotCurrent, match="HOCKLE_AUTO_MIGRATE"):
        create_app(settings)
    monkeypatch.setenv("HOCKLE_AUTO_MIGRATE", "false")
    assert Settings().auto_migrate is False
    monkeypatch.delenv("HOCKLE_AUTO_MIGRATE")
    create_app(Settings(data_dir=tmp_path / "data"))  # default: upgrade at start-up
    assert migrations.current(settings.registry_url) == migrations.head()


def test_the_command_line(url, tmp_path, capsys):
    from hockle.cli import main

    assert main(["db", "--url", url, "current"]) == 0
    assert "(no revision)" in capsys.readouterr().out
    assert main(["db", "--url", url, "check"]) == 1
    assert "run `hockle db upgrade`" in capsys.readouterr().out
    assert main(["db", "--url", url, "upgrade"]) == 0
    assert f"(no revision) -> {migrations.head()}" in capsys.readouterr().out
    assert main(["db", "--url", url, "check"]) == 0
    assert "models and schema agree" in capsys.readouterr().out
    assert main(["db", "--url", url, "downgrade", "-1"]) == 0
    assert main(["db", "--url", url, "current"]) == 0
    assert "behind" in capsys.readouterr().out
    assert main(["db", "--url", url, "upgrade"]) == 0
    assert main(["db", "--url", url, "history"]) == 0
    assert "0001_baseline" in capsys.readouterr().out


def test_the_command_line_names_the_setting_when_the_registry_is_unreachable(capsys,
                                                                             monkeypatch):
    from hockle.cli import main
    from service.settings import get_settings

    monkeypatch.setenv("HOCKLE_DATABASE_URL", "postgresql://nobody@127.0.0.1:1/none")
    get_settings.cache_clear()
    try:
        assert main(["db", "current"]) == 1
    finally:
        get_settings.cache_clear()
    err = capsys.readouterr().err
    assert "HOCKLE_DATABASE_URL" in err and "OperationalError" in err


def test_python_m_service_migrations(tmp_path):
    url = f"sqlite:///{tmp_path / 'r.db'}"
    out = subprocess.run([sys.executable, "-m", "service.migrations", "--url", url, "upgrade"],
                         cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert migrations.current(url) == migrations.head()


def test_a_worker_does_not_start_on_a_registry_it_cannot_use(tmp_path, monkeypatch):
    """``hockle worker`` / ``python -m worker`` check the schema before Celery starts: with
    HOCKLE_AUTO_MIGRATE=false and a registry not at head, they exit 1 saying what to run."""
    from service.settings import get_settings
    from worker.cli import schema_ready

    monkeypatch.setenv("HOCKLE_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("HOCKLE_AUTO_MIGRATE", "false")
    get_settings.cache_clear()
    try:
        problem = schema_ready()
        assert problem is not None and "HOCKLE_AUTO_MIGRATE" in problem
        monkeypatch.setenv("HOCKLE_AUTO_MIGRATE", "true")
        get_settings.cache_clear()
        assert schema_ready() is None
        assert migrations.current(get_settings().registry_url) == migrations.head()
    finally:
        get_settings.cache_clear()
