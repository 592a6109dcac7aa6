"""Operations that do only what is missing, for the revisions that adopt a registry made before
migrations (0001-0003).

A hockle before Alembic created its tables at start-up and added each newer nullable column
by ``ALTER TABLE``: such a registry can have any of the tables and columns of 0001-0003.
Run with these helpers, those revisions create only the tables, columns and indexes it lacks
and keep its rows; on a new database they create everything. Later revisions are written
with plain ``op`` calls: every registry that reaches them was made by these revisions.
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


def _inspector() -> sa.Inspector:
    return sa.inspect(op.get_bind())  # a new one each time: no stale cache after DDL


def has_table(name: str) -> bool:
    return _inspector().has_table(name)


def create_table_if_missing(name: str, *columns: sa.Column) -> bool:
    """``op.create_table`` unless the table exists; True when it was created."""
    if has_table(name):
        return False
    op.create_table(name, *columns)
    return True


def add_column_if_missing(table: str, column: sa.Column) -> bool:
    """``op.add_column`` unless the table has a column of that name; True when added."""
    if column.name in {c["name"] for c in _inspector().get_columns(table)}:
        return False
    op.add_column(table, column)
    return True


def create_index_if_missing(name: str, table: str, columns: list[str], *,
                            unique: bool = False) -> bool:
    """``op.create_index`` unless the table has an index of that name; True when made."""
    if name in {ix["name"] for ix in _inspector().get_indexes(table)}:
        return False
    op.create_index(name, table, columns, unique=unique)
    return True
