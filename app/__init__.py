"""scengen service: HTTP API, CLI, persistence, jobs, exports and dashboard."""

__version__ = "0.1.0"
