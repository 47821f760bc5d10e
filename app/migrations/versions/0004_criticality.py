"""scenario rows carry the criticality record: one column per field (issues 11, 13)

The names are riskcore.criticality.CRITICALITY_FIELDS as of this revision (a migration
must not follow later changes of that dict).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-24
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

COLUMNS = (
    ("t_p", sa.Float()),
    ("t_cross", sa.Float()),
    ("ttr_true", sa.Float()),
    ("ttr_manoeuvre", sa.Text()),
    ("a_req", sa.Float()),
    ("btn", sa.Float()),
    ("class", sa.Text()),
    ("none_collision", sa.Boolean()),
    ("none_impact_speed", sa.Float()),
    ("none_min_gap", sa.Float()),
    ("r157_cc_collision", sa.Boolean()),
    ("r157_cc_impact_speed", sa.Float()),
    ("r157_cc_min_gap", sa.Float()),
    ("r157_cc_t_brake", sa.Float()),
    ("rss_collision", sa.Boolean()),
    ("rss_impact_speed", sa.Float()),
    ("rss_min_gap", sa.Float()),
    ("rss_t_brake", sa.Float()),
    ("r_dep_tp", sa.Float()),
    ("r_ind_tp", sa.Float()),
    ("r_dep_cross", sa.Float()),
    ("r_ind_cross", sa.Float()),
    ("r_dep_tp_r157", sa.Float()),
    ("r_ind_tp_r157", sa.Float()),
    ("r_dep_cross_r157", sa.Float()),
    ("r_ind_cross_r157", sa.Float()),
    ("alarm_time", sa.Float()),
    ("risk_peak", sa.Float()),
)


def upgrade() -> None:
    with op.batch_alter_table("catalogue_scenarios") as batch:
        for name, type_ in COLUMNS:
            batch.add_column(sa.Column(name, type_, nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("catalogue_scenarios") as batch:
        for name, _ in reversed(COLUMNS):
            batch.drop_column(name)
