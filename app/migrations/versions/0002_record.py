"""scenario rows carry the scored record: drop the per-scenario seed, add the error

The builder is deterministic, so the per-scenario seed reproduced nothing (issue 13); a
vector the builder or riskcore refuses is now a row with ``error`` set.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("catalogue_scenarios") as batch:
        batch.drop_column("seed")
        batch.add_column(sa.Column("error", sa.Text(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("catalogue_scenarios") as batch:
        batch.drop_column("error")
        batch.add_column(sa.Column("seed", sa.BigInteger(), nullable=False,
                                   server_default="0"))
