"""Job ownership (issue 11, API keys): hockle_jobs.owner, the owner id of the key that
submitted the job (None without keys), and its index. Adds only what is missing
(service.migrations.adopt).

Revision ID: 0003_job_owner
Revises: 0002_heartbeats_sweeps
Create Date: 2026-11-22
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.migrations.adopt import add_column_if_missing, create_index_if_missing

revision = "0003_job_owner"
down_revision = "0002_heartbeats_sweeps"
branch_labels = None
depends_on = None


def upgrade() -> None:
    add_column_if_missing("hockle_jobs", sa.Column("owner", sa.String(64), nullable=True))
    create_index_if_missing("ix_hockle_jobs_owner", "hockle_jobs", ["owner"])


def downgrade() -> None:
    op.drop_index("ix_hockle_jobs_owner", table_name="hockle_jobs")
    with op.batch_alter_table("hockle_jobs") as batch:
        batch.drop_column("owner")
