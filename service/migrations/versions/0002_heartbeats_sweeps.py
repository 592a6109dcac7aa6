"""Job heartbeats and re-dispatch bookkeeping (issue 11); parameter sweeps (issue 13).

hockle_jobs gains heartbeat_at (the solving process's heartbeat: a stale one re-queues the
job), enqueued_at and dispatches (when the latest message was sent, how many were); the
hockle_sweeps table records sweeps. Adds only what is missing (service.migrations.adopt).

Revision ID: 0002_heartbeats_sweeps
Revises: 0001_baseline
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.migrations.adopt import (
    add_column_if_missing,
    create_index_if_missing,
    create_table_if_missing,
)

revision = "0002_heartbeats_sweeps"
down_revision = "0001_baseline"
branch_labels = None
depends_on = None


def upgrade() -> None:
    add_column_if_missing("hockle_jobs", sa.Column("heartbeat_at", sa.DateTime(), nullable=True))
    add_column_if_missing("hockle_jobs", sa.Column("enqueued_at", sa.DateTime(), nullable=True))
    add_column_if_missing("hockle_jobs", sa.Column("dispatches", sa.Integer(), nullable=True))

    create_table_if_missing(
        "hockle_sweeps",
        sa.Column("id", sa.String(36), primary_key=True),
        sa.Column("name", sa.String(200), nullable=True),
        sa.Column("combine", sa.String(8), nullable=False),
        sa.Column("parameters_json", sa.Text(), nullable=False),
        sa.Column("member_job_ids", sa.Text(), nullable=False),
        sa.Column("base_json", sa.Text(), nullable=False),
        sa.Column("owner", sa.String(64), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("dismissed_at", sa.DateTime(), nullable=True),
    )
    create_index_if_missing("ix_hockle_sweeps_owner", "hockle_sweeps", ["owner"])
    create_index_if_missing("ix_hockle_sweeps_created_at", "hockle_sweeps", ["created_at"])


def downgrade() -> None:
    op.drop_table("hockle_sweeps")
    with op.batch_alter_table("hockle_jobs") as batch:
        batch.drop_column("dispatches")
        batch.drop_column("enqueued_at")
        batch.drop_column("heartbeat_at")
