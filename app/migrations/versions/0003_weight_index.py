"""index the exposure weight: the status statistics are computed in SQL (issue 13)

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-24
"""

from __future__ import annotations

from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_index("ix_scenario_weight", "catalogue_scenarios",
                    ["catalogue_id", "exposure_weight"])


def downgrade() -> None:
    op.drop_index("ix_scenario_weight", "catalogue_scenarios")
