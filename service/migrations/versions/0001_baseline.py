"""Baseline: the registry of the first service release (jobs, job events, workers).

Creates what is missing only (service.migrations.adopt): on a registry made before
migrations it keeps the tables and rows there.

Revision ID: 0001_baseline
Revises:
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.migrations.adopt import create_index_if_missing, create_table_if_missing

revision = "0001_baseline"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    create_table_if_missing(
        "hockle_jobs",
        sa.Column("id", sa.String(36), primary_key=True),
        sa.Column("name", sa.String(200), nullable=True),
        sa.Column("state", sa.String(16), nullable=False),
        sa.Column("reason", sa.String(32), nullable=True),
        sa.Column("message", sa.Text(), nullable=True),
        sa.Column("spec_json", sa.Text(), nullable=False),
        sa.Column("spec_hash", sa.String(64), nullable=False),
        sa.Column("solver_version", sa.String(32), nullable=False),
        sa.Column("grid_points", sa.Integer(), nullable=False),
        sa.Column("n_steps", sa.Integer(), nullable=False),
        sa.Column("t_end", sa.Float(), nullable=False),
        sa.Column("idempotency_key", sa.String(200), nullable=True, unique=True),
        sa.Column("request_fingerprint", sa.String(64), nullable=True),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("updated_at", sa.DateTime(), nullable=False),
        sa.Column("started_at", sa.DateTime(), nullable=True),
        sa.Column("finished_at", sa.DateTime(), nullable=True),
        sa.Column("deadline_at", sa.DateTime(), nullable=True),
        sa.Column("progress", sa.Float(), nullable=False),
        sa.Column("sim_time", sa.Float(), nullable=False),
        sa.Column("step", sa.Integer(), nullable=False),
        sa.Column("wall_time", sa.Float(), nullable=True),
        sa.Column("eta_seconds", sa.Float(), nullable=True),
        sa.Column("failed_time", sa.Float(), nullable=True),
        sa.Column("failed_step", sa.Integer(), nullable=True),
        sa.Column("worker", sa.String(200), nullable=True),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("cancel_requested", sa.Boolean(), nullable=False),
        sa.Column("time_limit", sa.Float(), nullable=False),
        sa.Column("soft_time_limit", sa.Float(), nullable=False),
        sa.Column("wall_clock_budget", sa.Float(), nullable=False),
        sa.Column("result_path", sa.Text(), nullable=True),
        sa.Column("result_partial", sa.Boolean(), nullable=False),
    )
    for column in ("state", "spec_hash", "created_at", "deadline_at"):
        create_index_if_missing(f"ix_hockle_jobs_{column}", "hockle_jobs", [column])

    create_table_if_missing(
        "hockle_job_events",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("job_id", sa.String(36), nullable=False),
        sa.Column("at", sa.DateTime(), nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("attempt", sa.Integer(), nullable=True),
        sa.Column("worker", sa.String(200), nullable=True),
        sa.Column("detail", sa.Text(), nullable=True),
    )
    create_index_if_missing("ix_hockle_job_events_job_id", "hockle_job_events", ["job_id"])

    create_table_if_missing(
        "hockle_workers",
        sa.Column("name", sa.String(200), primary_key=True),
        sa.Column("last_seen", sa.DateTime(), nullable=False),
        sa.Column("current_job", sa.String(36), nullable=True),
    )


def downgrade() -> None:
    op.drop_table("hockle_workers")
    op.drop_table("hockle_job_events")
    op.drop_table("hockle_jobs")
