"""chunk rows keep their status values as one blob (issue 13: the first, uncached status
of a large catalogue read every scenario row)

Chunks stored before this revision have no blob; ``repository.stat_values`` reads those
from their scenario rows.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("catalogue_chunks") as batch:
        batch.add_column(sa.Column("stat_values", sa.LargeBinary(), nullable=True))
        batch.add_column(sa.Column("stat_columns", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("catalogue_chunks") as batch:
        batch.drop_column("stat_columns")
        batch.drop_column("stat_values")
