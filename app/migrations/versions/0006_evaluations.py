"""evaluations: campaign jobs of a system under test, their stored chunks and runs
(issue 24)

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-27
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

_TS = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "evaluations",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("model_id", sa.String(64), sa.ForeignKey("models.id", ondelete="RESTRICT"),
                  nullable=False),
        sa.Column("sut", sa.String(200), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("spec", sa.JSON(), nullable=False),
        sa.Column("runs_planned", sa.Integer(), nullable=False),
        sa.Column("runs_done", sa.Integer(), nullable=False),
        sa.Column("summary", sa.JSON(), nullable=True),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("created_at", _TS, nullable=False),
        sa.Column("updated_at", _TS, nullable=False),
        sa.Column("finished_at", _TS, nullable=True),
    )
    op.create_table(
        "evaluation_chunks",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("evaluation_id", sa.String(64),
                  sa.ForeignKey("evaluations.id", ondelete="CASCADE"), nullable=False),
        sa.Column("chunk_index", sa.Integer(), nullable=False),
        sa.Column("n_runs", sa.Integer(), nullable=False),
        sa.Column("collisions", sa.Integer(), nullable=False),
        sa.Column("data", sa.LargeBinary(), nullable=False),
        sa.Column("created_at", _TS, nullable=False),
        sa.UniqueConstraint("evaluation_id", "chunk_index", name="uq_evaluation_chunk"),
    )
    op.create_index("ix_evaluation_chunks_evaluation_id", "evaluation_chunks",
                    ["evaluation_id"])
    op.create_table(
        "evaluation_runs",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("evaluation_id", sa.String(64),
                  sa.ForeignKey("evaluations.id", ondelete="CASCADE"), nullable=False),
        sa.Column("run", sa.Integer(), nullable=False),
        sa.Column("chunk_index", sa.Integer(), nullable=False),
        sa.Column("weight_raw", sa.Float(), nullable=False),
        sa.Column("collided", sa.Boolean(), nullable=False),
        sa.Column("impact_speed", sa.Float(), nullable=True),
        sa.Column("r_dep_peak", sa.Float(), nullable=True),
        sa.Column("min_gap", sa.Float(), nullable=True),
        sa.Column("min_ttc", sa.Float(), nullable=True),
        sa.Column("vs_careful", sa.String(16), nullable=True),
        sa.Column("must_avoid", sa.Boolean(), nullable=True),
        sa.Column("violation", sa.Boolean(), nullable=True),
        sa.Column("record", sa.JSON(), nullable=False),
        sa.UniqueConstraint("evaluation_id", "run", name="uq_evaluation_run"),
    )
    op.create_index("ix_evaluation_run_impact", "evaluation_runs",
                    ["evaluation_id", "impact_speed"])
    op.create_index("ix_evaluation_run_rdep", "evaluation_runs",
                    ["evaluation_id", "r_dep_peak"])


def downgrade() -> None:
    op.drop_table("evaluation_runs")
    op.drop_table("evaluation_chunks")
    op.drop_table("evaluations")
