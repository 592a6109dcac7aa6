"""Alembic environment of hockle's registry: the models of :mod:`service.registry` are the
target; the connection or URL comes from ``config.attributes`` (:func:`service.migrations.
alembic_config`), else from hockle's settings (``HOCKLE_DATABASE_URL``). No alembic.ini."""
from __future__ import annotations

from alembic import context
from sqlalchemy import create_engine
from sqlalchemy.pool import NullPool

from service.migrations import VERSION_TABLE, include_name
from service.models import Base

config = context.config
target_metadata = Base.metadata
OPTIONS = dict(target_metadata=target_metadata, version_table=VERSION_TABLE,
               include_name=include_name, compare_type=True)


def _url() -> str:
    url = config.attributes.get("url")
    if url:
        return url
    from service.settings import get_settings

    return get_settings().registry_url


def run_offline() -> None:
    """``--sql``: write the SQL instead of running it."""
    context.configure(url=_url(), literal_binds=True, **OPTIONS)
    with context.begin_transaction():
        context.run_migrations()


def run_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        # service.migrations.upgrade: its transaction holds the migration lock
        context.configure(connection=connection, **OPTIONS)
        with context.begin_transaction():
            context.run_migrations()
        return
    engine = create_engine(_url(), poolclass=NullPool)
    try:
        with engine.connect() as conn:
            context.configure(connection=conn, **OPTIONS)
            with context.begin_transaction():
                context.run_migrations()
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_offline()
else:
    run_online()
