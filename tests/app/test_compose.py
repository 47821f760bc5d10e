"""docker-compose.yml, Dockerfile and .dockerignore: services and their wiring.

There is no Docker engine here, so the files are parsed and checked against what the
code expects: the settings the API reads, the CLI sub-command the image runs, the Dask
sub-commands that exist.
"""

from __future__ import annotations

import importlib.metadata
import json
import shlex
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "docker-compose.yml"
DOCKERFILE = ROOT / "Dockerfile"
DOCKERIGNORE = ROOT / ".dockerignore"


@pytest.fixture(scope="module")
def compose() -> dict[str, Any]:
    data = yaml.safe_load(COMPOSE.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


@pytest.fixture(scope="module")
def services(compose: dict[str, Any]) -> dict[str, Any]:
    result: dict[str, Any] = compose["services"]
    return result


def _command(service: dict[str, Any]) -> list[str]:
    cmd = service["command"]
    return shlex.split(cmd) if isinstance(cmd, str) else [str(c) for c in cmd]


def _env(service: dict[str, Any]) -> dict[str, str]:
    env = service.get("environment", {})
    if isinstance(env, list):  # ["KEY=value", ...]
        return dict(item.split("=", 1) for item in env)
    return {str(k): str(v) for k, v in env.items()}


def _volume_sources(service: dict[str, Any]) -> dict[str, str]:
    """Mount target -> source of the service's volumes (short or long syntax)."""
    out: dict[str, str] = {}
    for vol in service.get("volumes", []):
        if isinstance(vol, str):
            source, target = vol.split(":")[:2]
        else:
            source, target = vol["source"], vol["target"]
        out[target] = source
    return out


def _dockerfile_instructions() -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) pairs with line continuations joined, comments dropped."""
    logical: list[str] = []
    buffer = ""
    for raw in DOCKERFILE.read_text(encoding="utf-8").splitlines():
        line = raw.strip()
        if not buffer and (not line or line.startswith("#")):
            continue
        if line.endswith("\\"):
            buffer += line[:-1] + " "
            continue
        logical.append(buffer + line)
        buffer = ""
    pairs = []
    for line in logical:
        instruction, _, args = line.partition(" ")
        pairs.append((instruction.upper(), args.strip()))
    return pairs


def test_the_four_services(services: dict[str, Any]) -> None:
    assert set(services) == {"api", "postgres", "scheduler", "worker"}


def test_ports(services: dict[str, Any], compose: dict[str, Any]) -> None:
    # the API is published on the loopback only; nothing else is published at all
    assert services["api"]["ports"] == ["127.0.0.1:8000:8000"]
    for name in ("scheduler", "worker", "postgres"):
        assert "ports" not in services[name], name
        assert services[name]["networks"] == ["backend"], name
    assert compose["networks"]["backend"]["internal"] is True
    assert set(services["api"]["networks"]) == {"default", "backend"}
    assert _env(services["api"])["SCENGEN_API_KEY"] == "${SCENGEN_API_KEY:-}"


def test_postgres_has_credentials_a_health_check_and_a_named_volume(
        services: dict[str, Any], compose: dict[str, Any]) -> None:
    pg = services["postgres"]
    assert pg["image"] == "postgres:16"
    env = _env(pg)
    assert set(env) >= {"POSTGRES_USER", "POSTGRES_PASSWORD", "POSTGRES_DB"}
    test = pg["healthcheck"]["test"]
    command = test if isinstance(test, str) else " ".join(test[1:])
    assert "pg_isready" in command
    assert f"-U {env['POSTGRES_USER']}" in command and f"-d {env['POSTGRES_DB']}" in command
    sources = _volume_sources(pg)
    assert sources["/var/lib/postgresql/data"] in compose["volumes"]


def test_every_named_volume_is_declared(services: dict[str, Any],
                                        compose: dict[str, Any]) -> None:
    declared = set(compose.get("volumes") or {})
    used = {
        source for service in services.values()
        for source in _volume_sources(service).values()
        if not source.startswith((".", "/", "~"))
    }
    assert used, "expected named volumes"
    assert used <= declared


def test_depends_on_conditions(services: dict[str, Any]) -> None:
    api = services["api"]["depends_on"]
    assert api["postgres"]["condition"] == "service_healthy"
    assert api["scheduler"]["condition"] == "service_started"
    worker = services["worker"]["depends_on"]
    assert "scheduler" in worker
    if isinstance(worker, dict):
        assert worker["scheduler"]["condition"] == "service_started"


def test_api_scheduler_and_worker_share_one_build_and_image(services: dict[str, Any]) -> None:
    api = services["api"]
    assert api["build"]["context"] == "."
    assert api["build"]["dockerfile"] == "Dockerfile"
    for name in ("scheduler", "worker"):
        assert services[name]["build"] == api["build"], name
        assert services[name]["image"] == api["image"], name


def test_dask_commands_are_real_and_point_at_the_scheduler(services: dict[str, Any]) -> None:
    assert _command(services["scheduler"]) == ["dask", "scheduler"]
    assert _command(services["worker"]) == ["dask", "worker", "tcp://scheduler:8786"]
    # the `dask` console script and its sub-commands exist in the installed distributed
    scripts = {e.name for e in importlib.metadata.entry_points(group="console_scripts")}
    assert "dask" in scripts
    subcommands = {e.name for e in importlib.metadata.entry_points(group="dask_cli")}
    assert {"scheduler", "worker"} <= subcommands
    # the address the api and the worker use is the scheduler service's published port
    address = urlsplit(_env(services["api"])["SCENGEN_DASK_SCHEDULER"])
    assert (address.scheme, address.hostname, address.port) == ("tcp", "scheduler", 8786)
    assert str(address.port) in services["scheduler"]["expose"]


def test_api_environment_points_at_the_other_services(services: dict[str, Any]) -> None:
    env = _env(services["api"])
    assert env == {
        "SCENGEN_DATABASE_URL": "postgresql+psycopg://scengen:scengen@postgres:5432/scengen",
        "SCENGEN_DASK_SCHEDULER": "tcp://scheduler:8786",
        "SCENGEN_DATA_DIR": "/data",
        "SCENGEN_API_KEY": "${SCENGEN_API_KEY:-}",  # empty: no key required
    }
    url = urlsplit(env["SCENGEN_DATABASE_URL"])
    pg = _env(services["postgres"])
    assert url.hostname == "postgres" and url.port == 5432
    assert (url.username, url.password) == (pg["POSTGRES_USER"], pg["POSTGRES_PASSWORD"])
    assert url.path == f"/{pg['POSTGRES_DB']}"


def test_api_and_worker_share_the_data_volume(services: dict[str, Any]) -> None:
    api, worker = services["api"], services["worker"]
    assert _volume_sources(api)["/data"] == _volume_sources(worker)["/data"]
    assert _env(worker)["SCENGEN_DATA_DIR"] == _env(api)["SCENGEN_DATA_DIR"] == "/data"


def test_every_scengen_variable_is_a_settings_field(services: dict[str, Any],
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    from app.settings import Settings as settings_cls
    names = {
        key for service in services.values() for key in _env(service)
        if key.startswith("SCENGEN_")
    }
    assert names
    fields = set(settings_cls.model_fields)
    for name in sorted(names):
        assert name.removeprefix("SCENGEN_").lower() in fields, name
    # and the values parse into the fields
    for key, value in _env(services["api"]).items():
        monkeypatch.setenv(key, value)
    settings = settings_cls()
    assert str(settings.data_dir) == "/data"
    assert settings.dask_scheduler == "tcp://scheduler:8786"
    assert settings.database_url == (
        "postgresql+psycopg://scengen:scengen@postgres:5432/scengen")


def test_dockerfile_base_user_install_and_cmd() -> None:
    instructions = _dockerfile_instructions()
    assert instructions[0] == ("FROM", "python:3.11-slim")
    runs = " ".join(args for ins, args in instructions if ins == "RUN")
    # installs the project with the exact versions the suite passed on (constraints.txt)
    assert "pip install -c constraints.txt ." in runs
    users = [args for ins, args in instructions if ins == "USER"]
    assert users and users[-1] not in ("root", "0")
    copied = [args.split()[:-1] for ins, args in instructions if ins == "COPY"]
    assert any("pyproject.toml" in srcs and "constraints.txt" in srcs for srcs in copied)
    [cmd] = [args for ins, args in instructions if ins == "CMD"]
    argv = json.loads(cmd)  # exec form
    assert argv == ["scengen", "serve", "--host", "0.0.0.0", "--port", "8000"]


def test_dockerfile_cmd_and_api_command_are_real_scengen_subcommands(
        services: dict[str, Any]) -> None:
    from app.cli import build_parser

    [cmd] = [args for ins, args in _dockerfile_instructions() if ins == "CMD"]
    for argv in (json.loads(cmd), _command(services["api"])):
        assert argv[0] == "scengen"
        # the console script `scengen` is the CLI that build_parser() describes
        scripts = {e.name: e.value for e in
                   importlib.metadata.entry_points(group="console_scripts")}
        assert scripts["scengen"] == "app.cli:main"
        args = build_parser().parse_args(argv[1:])
        assert args.command == "serve"
        assert (args.host, args.port) == ("0.0.0.0", 8000)


def test_unknown_subcommand_would_be_caught() -> None:
    """The check above can fail: a made-up sub-command does not parse."""
    from app.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["serv", "--port", "8000"])


def test_dockerignore_keeps_local_state_out() -> None:
    entries = {
        line.strip() for line in DOCKERIGNORE.read_text(encoding="utf-8").splitlines()
        if line.strip() and not line.startswith("#")
    }
    assert {".venv", "var", ".git", ".mypy_cache", ".pytest_cache", ".ruff_cache"} <= entries
    assert "**/__pycache__" in entries
    # nothing the image needs is ignored
    for needed in ("pyproject.toml", "README.md", "app", "datasets", "riskcore", "sampler"):
        assert needed not in entries
