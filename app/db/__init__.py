"""Persistence: the ORM tables, the engine and migrations, and the repository functions."""

from app.db.database import Database, make_engine, migrate
from app.db.models import Base, CatalogueRow, ChunkRow, DatasetRow, ModelRow, ScenarioRow

__all__ = [
    "Base",
    "CatalogueRow",
    "ChunkRow",
    "Database",
    "DatasetRow",
    "ModelRow",
    "ScenarioRow",
    "make_engine",
    "migrate",
]
