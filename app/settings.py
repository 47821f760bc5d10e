"""Service settings: one pydantic-settings class, read from ``SCENGEN_*`` environment variables.

``get_settings()`` is cached; tests override it (``app.dependency_overrides[get_settings]``)
or build the app with ``create_app(settings)``.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Any

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

#: the names and addresses of this machine's loopback interface
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")


def default_data_dir() -> Path:
    """The store when SCENGEN_DATA_DIR is not set: the per-user data directory
    (``$XDG_DATA_HOME/scengen``, else ``~/.local/share/scengen``), whatever the current
    directory is, so the service and every CLI command find the same store."""
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base).expanduser() / "scengen"


class Settings(BaseSettings):
    """Everything the service can be told from outside. Names map to ``SCENGEN_<NAME>``."""

    model_config = SettingsConfigDict(env_prefix="SCENGEN_", extra="ignore")

    data_dir: Path = Field(
        default_factory=default_data_dir,
        description="directory for the SQLite file, uploaded data, the cached fitted model "
        "and catalogue trajectories (SCENGEN_DATA_DIR; default ~/.local/share/scengen, "
        "independent of the current directory)",
    )
    host: str = Field(default="127.0.0.1", min_length=1,
                      description="address scengen serve listens on (SCENGEN_HOST)")
    port: int = Field(default=8000, ge=1, le=65535,
                      description="port scengen serve listens on (SCENGEN_PORT)")
    database_url: str | None = Field(
        default=None,
        description="SQLAlchemy URL; default a SQLite file <data_dir>/scengen.db, e.g. "
        "postgresql+psycopg://postgres@127.0.0.1:5432/test (SCENGEN_DATABASE_URL)",
    )
    dask_scheduler: str | None = Field(
        default=None,
        description="address of a dask.distributed scheduler (tcp://host:8786); when set "
        "catalogue chunks run there instead of on the local process pool",
    )
    local_workers: int = Field(
        default=2, ge=0,
        description="processes of the local pool; 0 runs chunks inline in the job thread",
    )
    sync_n_limit: int = Field(default=500, ge=1, description="largest n of POST /scenarios")
    catalogue_n_limit: int = Field(default=1_000_000, ge=1, description="largest catalogue n")
    upload_limit_bytes: int = Field(
        default=50 * 1024 * 1024, ge=1, description="largest dataset upload (all files)"
    )
    upload_expanded_limit_bytes: int = Field(
        default=200 * 1024 * 1024, ge=1,
        description="largest dataset upload once decompressed (.gz/.bz2/.xz streams, "
        "Parquet row groups); 413 above")
    chunk_size: int = Field(default=250, ge=1, description="scenarios per catalogue chunk")
    store_trajectories: bool = Field(
        default=True,
        description="keep each catalogue scenario's trajectories in per-chunk files; when "
        "false they are rebuilt from the stored parameters and seed on export",
    )
    default_model_options: dict[str, Any] = Field(
        default_factory=dict,
        description="keyword options of sampler.model.CutInGMM for the default model fitted "
        "on the embedded data at first start (JSON in SCENGEN_DEFAULT_MODEL_OPTIONS); the "
        "cached model is keyed by the data hash and these options",
    )
    api_key: SecretStr | None = Field(
        default=None,
        description="when set, POST/PUT/PATCH/DELETE need it in the X-API-Key header "
        "(or Authorization: Bearer), and so do the costly reads (app.guards.COSTLY_READS: "
        "compare, the dashboard's shift, rates and fit, the exports); reads of what is "
        "stored stay open (SCENGEN_API_KEY)")
    trusted_hosts: list[str] = Field(
        default_factory=lambda: list(LOOPBACK_NAMES),
        description="host names the service answers to (the request's Host header, port "
        "left out); any other Host gets 400, so a web page cannot reach a service on "
        "loopback through DNS rebinding. Default the loopback names; SCENGEN_HOST is added "
        "when it is a name or a specific address. '*.example.org' trusts the subdomains, "
        "'*' every host. JSON in SCENGEN_TRUSTED_HOSTS, e.g. '[\"scengen.lab.example\"]'")
    # quotas of one client (app/quotas.py): 429 with Retry-After naming the setting
    client_jobs_limit: int = Field(
        default=4, ge=1, description="most jobs (catalogues, evaluations) one client may "
        "have queued or running at once")
    client_queued_scenarios_limit: int = Field(
        default=200_000, ge=1, description="most scenarios one client may have in its "
        "queued and running jobs together (about 40 min of work on 2 cores)")
    sync_budget_seconds: float = Field(
        default=10.0, gt=0, description="longest a synchronous request may sample or "
        "estimate (POST /scenarios, GET /models/compare, the dashboard's shift and rates): "
        "past it the request is stopped and answered 422 saying how to get the work as a "
        "job (app/budget.py); a client that disconnects stops its work the same way")
    running_jobs_limit: int = Field(
        default=8, ge=1, description="most jobs the service runs at once (each client's "
        "oldest first, the client with the fewest running first); the running jobs share "
        "the workers chunk by chunk, a free worker going to the client with the fewest "
        "chunks in flight (app/jobs/fair.py), so a huge job does not hold the others back")
    quota_retry_after: int = Field(
        default=60, ge=1, description="seconds a client over a quota is told to wait "
        "(Retry-After)")
    # limits on what one request may ask for (app/limits.py): 422/413 naming the setting
    body_limit_bytes: int = Field(
        default=10 * 1024 * 1024, ge=1,
        description="largest request body other than a dataset upload (413 above)")
    constraints_limit: int = Field(default=32, ge=1,
                                   description="most constraints in one request")
    constraint_length_limit: int = Field(default=200, ge=1,
                                         description="longest constraint (characters)")
    risk_objects_limit: int = Field(default=16, ge=1,
                                    description="most objects in a POST /risk scenario")
    risk_steps_limit: int = Field(default=1000, ge=2,
                                  description="most time steps in a POST /risk scenario")
    model_n_init_limit: int = Field(default=20, ge=1,
                                    description="largest n_init of POST /models")
    model_max_iter_limit: int = Field(default=2000, ge=1,
                                      description="largest max_iter of POST /models")
    model_cv_folds_limit: int = Field(default=20, ge=2,
                                      description="largest cv_folds of POST /models")
    model_report_samples_limit: int = Field(
        default=200_000, ge=100, description="largest n_report_samples of POST /models")
    model_k_limit: int = Field(default=16, ge=1,
                               description="largest number of components of POST /models")
    resume_jobs: bool = Field(
        default=True, description="resume unfinished catalogue jobs when the service starts"
    )
    warm_start: bool = Field(
        default=True, description="at start, in the background: start the pool's workers "
        "and load their compiled kernels, and estimate the default model's P(B) and the "
        "model interval of the default region, so the first request does not wait for them")

    @property
    def resolved_database_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'scengen.db').resolve()}"


@lru_cache
def get_settings() -> Settings:
    return Settings()
