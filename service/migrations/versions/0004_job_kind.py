"""Jobs of their own kind (issue 42, continuation jobs): hockle_jobs.kind, "dynamic" for
every job recorded before (the server default fills the existing rows) or
"continuation". Adds it only where missing (service.migrations.adopt), as a registry
adopted from before migrations is brought through every revision.

Revision ID: 0004_job_kind
Revises: 0003_job_owner
Create Date: 2026-11-25
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

from service.migrations.adopt import add_column_if_missing

revision = "0004_job_kind"
down_revision = "0003_job_owner"
branch_labels = None
depends_on = None


def upgrade() -> None:
    add_column_if_missing("hockle_jobs", sa.Column("kind", sa.String(16), nullable=False,
                                                   server_default="dynamic"))


def downgrade() -> None:
    with op.batch_alter_table("hockle_jobs") as batch:
        batch.drop_column("kind")
