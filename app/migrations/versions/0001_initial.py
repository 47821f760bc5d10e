"""initial schema: datasets, models, catalogues, chunks, scenarios

Revision ID: 0001
Revises:
Create Date: 2026-11-21
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None

_TS = sa.DateTime(timezone=True)


def upgrade() -> None:
    op.create_table(
        "datasets",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("name", sa.String(200), nullable=False),
        sa.Column("kind", sa.String(32), nullable=False),
        sa.Column("embedded", sa.Boolean(), nullable=False),
        sa.Column("data_hash", sa.String(64), nullable=False),
        sa.Column("n_cutins", sa.Integer(), nullable=False),
        sa.Column("table_path", sa.Text(), nullable=False),
        sa.Column("report", sa.JSON(), nullable=False),
        sa.Column("created_at", _TS, nullable=False),
    )
    op.create_table(
        "models",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("dataset_id", sa.String(64),
                  sa.ForeignKey("datasets.id", ondelete="CASCADE"), nullable=False),
        sa.Column("is_default", sa.Boolean(), nullable=False),
        sa.Column("options", sa.JSON(), nullable=False),
        sa.Column("n_components", sa.Integer(), nullable=False),
        sa.Column("model_hash", sa.String(64), nullable=False),
        sa.Column("model_json", sa.Text(), nullable=False),
        sa.Column("bic_curve", sa.JSON(), nullable=False),
        sa.Column("fit_report", sa.JSON(), nullable=False),
        sa.Column("created_at", _TS, nullable=False),
    )
    op.create_table(
        "catalogues",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("model_id", sa.String(64),
                  sa.ForeignKey("models.id", ondelete="RESTRICT"), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("n", sa.Integer(), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("chunk_size", sa.Integer(), nullable=False),
        sa.Column("n_chunks", sa.Integer(), nullable=False),
        sa.Column("spec", sa.JSON(), nullable=False),
        sa.Column("p_region", sa.JSON(), nullable=True),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("created_at", _TS, nullable=False),
        sa.Column("updated_at", _TS, nullable=False),
        sa.Column("finished_at", _TS, nullable=True),
    )
    op.create_table(
        "catalogue_chunks",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("catalogue_id", sa.String(64),
                  sa.ForeignKey("catalogues.id", ondelete="CASCADE"), nullable=False),
        sa.Column("chunk_index", sa.Integer(), nullable=False),
        sa.Column("n_scenarios", sa.Integer(), nullable=False),
        sa.Column("file_path", sa.Text(), nullable=True),
        sa.Column("sha256", sa.String(64), nullable=True),
        sa.Column("diagnostics", sa.JSON(), nullable=False),
        sa.Column("created_at", _TS, nullable=False),
        sa.UniqueConstraint("catalogue_id", "chunk_index", name="uq_chunk_index"),
    )
    op.create_index("ix_catalogue_chunks_catalogue_id", "catalogue_chunks", ["catalogue_id"])
    op.create_table(
        "catalogue_scenarios",
        sa.Column("id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("catalogue_id", sa.String(64),
                  sa.ForeignKey("catalogues.id", ondelete="CASCADE"), nullable=False),
        sa.Column("idx", sa.Integer(), nullable=False),
        sa.Column("chunk_index", sa.Integer(), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("params", sa.JSON(), nullable=False),
        sa.Column("ttc", sa.Float(), nullable=True),
        sa.Column("risk", sa.Float(), nullable=True),
        sa.Column("exposure_weight", sa.Float(), nullable=True),
        sa.Column("summary", sa.JSON(), nullable=False),
        sa.UniqueConstraint("catalogue_id", "idx", name="uq_scenario_idx"),
    )
    op.create_index("ix_scenario_risk", "catalogue_scenarios", ["catalogue_id", "risk"])
    op.create_index("ix_scenario_ttc", "catalogue_scenarios", ["catalogue_id", "ttc"])


def downgrade() -> None:
    op.drop_index("ix_scenario_ttc", "catalogue_scenarios")
    op.drop_index("ix_scenario_risk", "catalogue_scenarios")
    op.drop_table("catalogue_scenarios")
    op.drop_index("ix_catalogue_chunks_catalogue_id", "catalogue_chunks")
    op.drop_table("catalogue_chunks")
    op.drop_table("catalogues")
    op.drop_table("models")
    op.drop_table("datasets")
