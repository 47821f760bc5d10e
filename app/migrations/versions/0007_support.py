"""catalogue scenarios keep their data support (issue 25): class, distance to the nearest
real cut-in, range excess as columns, the rest as JSON

Rows stored before this revision have null support (the API shows null).

Revision ID: 0007
Revises: 0006
Create Date: 2026-11-27
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("catalogue_scenarios") as batch:
        batch.add_column(sa.Column("support", sa.Text(), nullable=True))
        batch.add_column(sa.Column("support_distance", sa.Float(), nullable=True))
        batch.add_column(sa.Column("support_excess", sa.Float(), nullable=True))
        batch.add_column(sa.Column("support_detail", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("catalogue_scenarios") as batch:
        for name in ("support_detail", "support_excess", "support_distance", "support"):
            batch.drop_column(name)
