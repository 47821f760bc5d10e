"""Alembic migrations of the service's database (run at start-up by ``app.db.migrate``)."""
