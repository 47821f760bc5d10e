"""Tables of the service (SQLAlchemy 2 typed ORM). The schema is created by Alembic
migrations in ``app/migrations/``; change both together.

Floats that may be infinite (TTC, TTR) are stored as IEEE doubles (SQLite REAL and
PostgreSQL double precision both hold +inf); JSON columns never hold non-finite numbers
(``app.jsonconv.encode`` writes them as "Infinity" strings first).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, ClassVar

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


def utcnow() -> datetime:
    return datetime.now(UTC)


class Base(DeclarativeBase):
    type_annotation_map: ClassVar[dict[Any, Any]] = {dict[str, Any]: JSON, list[Any]: JSON}


class DatasetRow(Base):
    """A source of cut-ins: the embedded TNO data or an upload, with its parameter table."""

    __tablename__ = "datasets"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    kind: Mapped[str] = mapped_column(String(32))  # embedded | highd | egocentric
    embedded: Mapped[bool] = mapped_column(Boolean, default=False)
    data_hash: Mapped[str] = mapped_column(String(64))
    n_cutins: Mapped[int] = mapped_column(Integer)
    table_path: Mapped[str] = mapped_column(Text)  # relative to the data dir (Parquet)
    report: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ModelRow(Base):
    """A fitted cut-in GMM (the JSON of ``CutInGMM.to_json``)."""

    __tablename__ = "models"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    dataset_id: Mapped[str] = mapped_column(ForeignKey("datasets.id", ondelete="CASCADE"))
    is_default: Mapped[bool] = mapped_column(Boolean, default=False)
    options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    n_components: Mapped[int] = mapped_column(Integer)
    model_hash: Mapped[str] = mapped_column(String(64))
    model_json: Mapped[str] = mapped_column(Text)
    bic_curve: Mapped[list[Any]] = mapped_column(JSON, default=list)
    fit_report: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class CatalogueRow(Base):
    """A catalogue job and its result summary."""

    __tablename__ = "catalogues"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    model_id: Mapped[str] = mapped_column(ForeignKey("models.id", ondelete="RESTRICT"))
    status: Mapped[str] = mapped_column(String(16))  # queued|running|done|failed|cancelled
    n: Mapped[int] = mapped_column(Integer)
    seed: Mapped[int] = mapped_column(BigInteger)
    chunk_size: Mapped[int] = mapped_column(Integer)
    n_chunks: Mapped[int] = mapped_column(Integer)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)  # the full, JSON-able job spec
    p_region: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class ChunkRow(Base):
    """One finished chunk of a catalogue. ``(catalogue_id, chunk_index)`` is unique."""

    __tablename__ = "catalogue_chunks"
    __table_args__ = (UniqueConstraint("catalogue_id", "chunk_index", name="uq_chunk_index"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    catalogue_id: Mapped[str] = mapped_column(
        ForeignKey("catalogues.id", ondelete="CASCADE"), index=True
    )
    chunk_index: Mapped[int] = mapped_column(Integer)
    n_scenarios: Mapped[int] = mapped_column(Integer)
    file_path: Mapped[str | None] = mapped_column(Text, nullable=True)  # relative to data dir
    sha256: Mapped[str | None] = mapped_column(String(64), nullable=True)
    diagnostics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # the chunk's status values (repository.stat_values: rows x stat_columns, float64, NaN
    # = null) as .npy bytes, so an uncached status reads one blob per chunk, not every row
    stat_values: Mapped[bytes | None] = mapped_column(LargeBinary, nullable=True)
    stat_columns: Mapped[list[str] | None] = mapped_column(JSON, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ScenarioRow(Base):
    """One scenario of a catalogue: parameters and scores (trajectories live in chunk files)."""

    __tablename__ = "catalogue_scenarios"
    __table_args__ = (
        UniqueConstraint("catalogue_id", "idx", name="uq_scenario_idx"),
        Index("ix_scenario_risk", "catalogue_id", "risk"),
        Index("ix_scenario_ttc", "catalogue_id", "ttc"),
        Index("ix_scenario_weight", "catalogue_id", "exposure_weight"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    catalogue_id: Mapped[str] = mapped_column(ForeignKey("catalogues.id", ondelete="CASCADE"))
    idx: Mapped[int] = mapped_column(Integer)  # 0 .. n-1 within the catalogue
    chunk_index: Mapped[int] = mapped_column(Integer)
    params: Mapped[dict[str, Any]] = mapped_column(JSON)
    ttc: Mapped[float | None] = mapped_column(Float, nullable=True)
    risk: Mapped[float | None] = mapped_column(Float, nullable=True)  # = risk_peak
    exposure_weight: Mapped[float | None] = mapped_column(Float, nullable=True)
    #: the record's score fields (``sampler.scenario.record.SCORE_FIELDS``; inf as "Infinity")
    summary: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    #: why the vector has no scores ("build: ..." / "score: ..."), None when scored
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    # the criticality record (riskcore.criticality.CRITICALITY_FIELDS), one column each so
    # that catalogues are filtered and ranked in SQL; +inf stored as IEEE inf
    t_p: Mapped[float | None] = mapped_column(Float, nullable=True)
    t_cross: Mapped[float | None] = mapped_column(Float, nullable=True)
    ttr_true: Mapped[float | None] = mapped_column(Float, nullable=True)
    ttr_manoeuvre: Mapped[str | None] = mapped_column(Text, nullable=True)
    a_req: Mapped[float | None] = mapped_column(Float, nullable=True)
    btn: Mapped[float | None] = mapped_column(Float, nullable=True)
    class_: Mapped[str | None] = mapped_column("class", Text, nullable=True)
    none_collision: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    none_impact_speed: Mapped[float | None] = mapped_column(Float, nullable=True)
    none_min_gap: Mapped[float | None] = mapped_column(Float, nullable=True)
    r157_cc_collision: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    r157_cc_impact_speed: Mapped[float | None] = mapped_column(Float, nullable=True)
    r157_cc_min_gap: Mapped[float | None] = mapped_column(Float, nullable=True)
    r157_cc_t_brake: Mapped[float | None] = mapped_column(Float, nullable=True)
    rss_collision: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    rss_impact_speed: Mapped[float | None] = mapped_column(Float, nullable=True)
    rss_min_gap: Mapped[float | None] = mapped_column(Float, nullable=True)
    rss_t_brake: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_dep_tp: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_ind_tp: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_dep_cross: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_ind_cross: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_dep_tp_r157: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_ind_tp_r157: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_dep_cross_r157: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_ind_cross_r157: Mapped[float | None] = mapped_column(Float, nullable=True)
    alarm_time: Mapped[float | None] = mapped_column(Float, nullable=True)
    risk_peak: Mapped[float | None] = mapped_column(Float, nullable=True)
    # the data support (issue 25, sampler.model.support); null: stored before, or the
    # model has no training rows
    support: Mapped[str | None] = mapped_column(Text, nullable=True)
    support_distance: Mapped[float | None] = mapped_column(Float, nullable=True)
    support_excess: Mapped[float | None] = mapped_column(Float, nullable=True)
    #: support_nearest, density_pct, support_outside
    support_detail: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)


class EvaluationRow(Base):
    """A campaign job (issue 24): a system under test driven through importance-sampled
    cut-ins (``sampler.campaign.evaluate``); ``summary`` once it is done."""

    __tablename__ = "evaluations"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    model_id: Mapped[str] = mapped_column(ForeignKey("models.id", ondelete="RESTRICT"))
    sut: Mapped[str] = mapped_column(String(200))
    status: Mapped[str] = mapped_column(String(16))  # queued|running|done|failed|cancelled
    seed: Mapped[int] = mapped_column(BigInteger)
    #: the campaign's spec: constraints, n, rhw, max_runs, batch_size, sut_params, settings
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    runs_planned: Mapped[int] = mapped_column(Integer)
    runs_done: Mapped[int] = mapped_column(Integer, default=0)
    #: ``CampaignResult.summary()`` (JSON-safe) once done
    summary: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class EvaluationChunkRow(Base):
    """One finished chunk of a campaign: ``sampler.campaign.ChunkResult.to_dict()`` as
    zlib-compressed JSON, replayed through ``evaluate(..., stored=...)`` on resume."""

    __tablename__ = "evaluation_chunks"
    __table_args__ = (UniqueConstraint("evaluation_id", "chunk_index",
                                       name="uq_evaluation_chunk"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    evaluation_id: Mapped[str] = mapped_column(
        ForeignKey("evaluations.id", ondelete="CASCADE"), index=True)
    chunk_index: Mapped[int] = mapped_column(Integer)
    n_runs: Mapped[int] = mapped_column(Integer)
    collisions: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class EvaluationRunRow(Base):
    """One simulated run of a campaign (draws outside the region or the physical bounds
    are not run and have no row). ``weight_raw`` = p/q in the model's z-space; the run's
    weight in P is ``weight_raw / P(B)`` (the summary's ``p_bounds``)."""

    __tablename__ = "evaluation_runs"
    __table_args__ = (
        UniqueConstraint("evaluation_id", "run", name="uq_evaluation_run"),
        Index("ix_evaluation_run_impact", "evaluation_id", "impact_speed"),
        Index("ix_evaluation_run_rdep", "evaluation_id", "r_dep_peak"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    evaluation_id: Mapped[str] = mapped_column(
        ForeignKey("evaluations.id", ondelete="CASCADE"))
    run: Mapped[int] = mapped_column(Integer)  # index over all draws of the campaign
    chunk_index: Mapped[int] = mapped_column(Integer)
    weight_raw: Mapped[float] = mapped_column(Float)
    collided: Mapped[bool] = mapped_column(Boolean)
    impact_speed: Mapped[float | None] = mapped_column(Float, nullable=True)
    r_dep_peak: Mapped[float | None] = mapped_column(Float, nullable=True)
    min_gap: Mapped[float | None] = mapped_column(Float, nullable=True)
    min_ttc: Mapped[float | None] = mapped_column(Float, nullable=True)
    vs_careful: Mapped[str | None] = mapped_column(String(16), nullable=True)
    must_avoid: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    violation: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    #: the run's record: seed (as a string: uint64), parameters by name, every outcome
    record: Mapped[dict[str, Any]] = mapped_column(JSON)
