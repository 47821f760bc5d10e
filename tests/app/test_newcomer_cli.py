"""Issue 14, the newcomer's command line: one store whatever the current directory, one
option grammar, one-line errors, SCENGEN_HOST/PORT, what `make run` installs."""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.cli import build_parser, main
from app.settings import Settings, get_settings
from tests.app.factories import copy_model_cache

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "cut-in.json"


@pytest.fixture
def no_store_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """No SCENGEN_* variables; the per-user data directory under tmp_path/xdg."""
    for key in list(os.environ):
        if key.startswith("SCENGEN_"):
            monkeypatch.delenv(key)
    xdg = tmp_path / "xdg"
    monkeypatch.setenv("XDG_DATA_HOME", str(xdg))
    get_settings.cache_clear()
    yield xdg / "scengen"
    get_settings.cache_clear()


# --------------------------------------------------------------------------- item 2
def test_default_store_does_not_follow_the_current_directory(
        no_store_env: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = []
    for sub in ("a", "b/c"):
        (tmp_path / sub).mkdir(parents=True)
        monkeypatch.chdir(tmp_path / sub)
        seen.append(Path(Settings().data_dir).resolve())
    assert seen == [no_store_env.resolve(), no_store_env.resolve()]


def test_a_read_command_elsewhere_creates_nothing_and_names_the_store(
        no_store_env: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert main(["catalogue", "export", "cat-123", "--format", "csv",
                 "-o", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("scengen: error:") and "\n" not in err
    assert str(no_store_env.resolve()) in err
    assert list(elsewhere.iterdir()) == []          # no ./var/scengen.db
    assert not no_store_env.exists()                # and no empty store either


@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_not_found_names_the_store_and_data_dir_works_before_and_after_the_command(
        store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    other = tmp_path / "other"
    copy_model_cache(store, other)
    monkeypatch.setenv("SCENGEN_DATA_DIR", str(tmp_path / "not-this-one"))
    assert main(["catalogue", "create", "-n", "2", "--no-score", "-q",
                 "--data-dir", str(other)]) == 0
    cid = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["id"]
    assert (other / "scengen.db").is_file()
    assert main(["--data-dir", str(other), "catalogue", "status", cid]) == 0
    assert json.loads(capsys.readouterr().out)["id"] == cid
    assert main(["catalogue", "status", "cat-nope", "--data-dir", str(other)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"scengen: error: catalogue 'cat-nope' not found in the store at "
                   f"{other.resolve()}")


# --------------------------------------------------------------------------- item 3
def _subparsers(parser: argparse.ArgumentParser,
                path: str = "scengen") -> Iterator[tuple[str, argparse.ArgumentParser]]:
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _subparsers(sub, f"{path} {name}")


#: short option -> (its long form, where the value goes)
GRAMMAR = {"-n": ("--n", "n"), "-c": ("--constraint", "constraints"),
           "-o": ("--out", "output"), "-q": ("--quiet", "quiet")}


def test_every_option_has_help_and_short_options_mean_the_same_everywhere() -> None:
    seen: dict[str, int] = dict.fromkeys(GRAMMAR, 0)
    for path, parser in _subparsers(build_parser()):
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                continue
            if action.option_strings:
                assert action.help and action.help is not argparse.SUPPRESS, \
                    f"{path} {action.option_strings} has no help"
            for short, (long, dest) in GRAMMAR.items():
                if short in action.option_strings or long in action.option_strings:
                    seen[short] += 1
                    assert short in action.option_strings and long in action.option_strings, \
                        f"{path}: {action.option_strings} is half of {short}/{long}"
                    assert action.dest == dest, f"{path}: {short} goes to {action.dest}"
    assert all(count >= 2 for count in seen.values()), seen


def test_catalogue_create_takes_the_short_options(store: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["catalogue", "create", "-n", "3", "-c", "ttc<3", "--seed", "2", "-q",
                 "--no-score"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out.strip().splitlines()[-1])["status"] == "done"
    assert "it/s" not in err and "scenario/s" not in err  # -q: no bar


@pytest.mark.slow
def test_sample_uses_the_default_model_when_none_is_given(
        store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.jsonl"
    assert main(["sample", "-n", "4", "-c", "ttc<3", "--seed", "1", "-q",
                 "-o", str(out)]) == 0
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 4
    assert all(r["derived"]["ttc"] < 3 for r in rows)
    # the same by id, as in 'catalogue create --model'
    out2 = tmp_path / "s2.jsonl"
    assert main(["sample", "--model", "default", "-n", "4", "-c", "ttc<3", "--seed", "1",
                 "-q", "-o", str(out2)]) == 0
    assert out2.read_text() == out.read_text()
    assert main(["sample", "--model", "mdl-nope", "-n", "2", "-q"]) == 2
    assert "'mdl-nope' not found in the store at" in capsys.readouterr().err


# --------------------------------------------------------------------------- item 4
@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_export_to_a_missing_directory_is_one_line_exit_2(
        store: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["catalogue", "create", "-n", "2", "--no-score", "-q"]) == 0
    cid = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["id"]
    assert main(["catalogue", "export", cid, "--format", "xosc",
                 "--out", "/nonexistent/x.zip"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("scengen: error: --out:")
    assert "/nonexistent" in err and "Traceback" not in err


@pytest.mark.slow  # >= 3 s (issue 26 item 8: pytest --durations, loaded machine)
def test_an_export_failure_inside_the_service_is_one_line(
        store: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    from app.errors import ServiceError

    def broken(*_: Any, **__: Any) -> Any:
        raise ServiceError("export of catalogue x failed: disk full")

    monkeypatch.setattr("app.services.catalogues.export", broken)
    assert main(["catalogue", "create", "-n", "2", "--no-score", "-q"]) == 0
    cid = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["id"]
    assert main(["catalogue", "export", cid, "-o", str(store / "x.csv")]) == 2
    assert capsys.readouterr().err == "scengen: error: export of catalogue x failed: disk full\n"


@pytest.mark.slow
def test_risk_into_a_closed_pipe_is_quiet() -> None:
    # `scengen risk f.json | head -c 100`: the reader goes away after 100 bytes
    with subprocess.Popen([sys.executable, "-m", "app.cli", "risk", str(EXAMPLE)],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT) as proc:
        assert proc.stdout is not None and proc.stderr is not None
        head = proc.stdout.read(100)
        proc.stdout.close()
        err = proc.stderr.read().decode()
        proc.wait(timeout=120)
    assert head.startswith(b"{")
    assert err == ""
    assert proc.returncode == 0


@pytest.mark.parametrize(("host", "key", "warned"), [
    ("0.0.0.0", None, True), ("192.168.1.5", None, True), ("::", None, True),
    ("0.0.0.0", "k3y", False), ("127.0.0.1", None, False), ("localhost", None, False),
    ("::1", None, False), ("127.0.0.2", None, False)])
def test_serve_beyond_loopback_without_a_key_warns(
        no_store_env: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str], host: str, key: str | None,
        warned: bool) -> None:
    import app.cli.service as service_cli

    monkeypatch.setattr(service_cli, "_listen_and_serve", lambda host, port, level: None)
    monkeypatch.setenv("SCENGEN_HOST", "127.0.0.1")  # recorded, so serve's change is undone
    if key is None:
        monkeypatch.delenv("SCENGEN_API_KEY", raising=False)
    else:
        monkeypatch.setenv("SCENGEN_API_KEY", key)
    get_settings.cache_clear()
    assert main(["serve", "--host", host]) == 0
    err = capsys.readouterr().err
    assert ("WARNING" in err and "SCENGEN_API_KEY" in err) is warned, err
    assert get_settings().host == host  # the app's settings (trusted hosts) see the bind
    get_settings.cache_clear()


# --------------------------------------------------------------------------- item 5
def test_serve_honours_scengen_host_and_port(no_store_env: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    import app.cli.service as service_cli

    calls: list[dict[str, Any]] = []
    monkeypatch.setattr(service_cli, "_listen_and_serve",
                        lambda host, port, level: calls.append({"host": host, "port": port}))
    monkeypatch.setenv("SCENGEN_HOST", "127.0.0.2")
    monkeypatch.setenv("SCENGEN_PORT", "8123")
    get_settings.cache_clear()
    assert main(["serve"]) == 0
    assert main(["serve", "--port", "9001"]) == 0
    assert [(c["host"], c["port"]) for c in calls] == [("127.0.0.2", 8123),
                                                        ("127.0.0.2", 9001)]


def test_serve_on_a_port_in_use_stops_before_the_app_starts(
        no_store_env: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A second service on a port already listening: one line naming --port, exit 2,
    and the app (whose start resumes the store's jobs) never starts."""
    import socket

    import uvicorn

    started: list[object] = []
    monkeypatch.setattr(uvicorn, "Server", lambda config: started.append(config))
    busy = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = busy.getsockname()[1]
    try:
        get_settings.cache_clear()
        code = main(["serve", "--host", "127.0.0.1", "--port", str(port)])
    finally:
        busy.close()
        get_settings.cache_clear()
    err = capsys.readouterr().err.strip()
    assert code == 2 and started == []
    assert len(err.splitlines()) == 1 and err.startswith("scengen: error: --port:"), err
    assert f"127.0.0.1:{port}" in err and "in use" in err


def test_readme_configuration_table_lists_every_setting() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    rows = set(re.findall(r"^\| `(SCENGEN_[A-Z_]+)` \|", readme, flags=re.M))
    wanted = {f"SCENGEN_{name.upper()}" for name in Settings.model_fields}
    assert wanted - rows == set()
    assert {"SCENGEN_HOST", "SCENGEN_PORT"} <= rows


# --------------------------------------------------------------------------- item 7
def test_make_run_installs_only_the_runtime_dependencies(tmp_path: Path) -> None:
    run = subprocess.run(["make", "-n", "-B", "run", "VENV=" + str(tmp_path / "v")],
                         cwd=ROOT, capture_output=True, text=True, check=True).stdout
    installs = [line for line in run.splitlines() if "pip install" in line
                and "--upgrade pip" not in line]
    assert installs and not any("[dev]" in line for line in installs), run
    test = subprocess.run(["make", "-n", "-B", "pytest", "VENV=" + str(tmp_path / "v")],
                          cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert any("[dev]" in line for line in test.splitlines() if "pip install" in line)


def test_embedded_dataset_name_gives_the_number_used() -> None:
    from app.services.store import EMBEDDED_NAME
    from datasets.embedded import default_parameter_table

    used = len(default_parameter_table())
    assert f"{used} usable of 297" in EMBEDDED_NAME


# --------------------------------------------------------------------------- item 6
def test_a_stage_that_ends_early_shows_its_real_total(
        capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli.sampling import StageBars

    bars = StageBars(quiet=False)
    bars("pilot", 20_480, 1 << 20)  # the pilot stops after 2 % of its budget
    bars("rejection", 5, 10)
    bars("rejection", 10, 10)
    bars.close()
    err = capsys.readouterr().err
    pilot = [part for part in re.split(r"[\r\n]", err) if part.startswith("pilot")]
    assert pilot and "20,480 (enough before the budget of 1,048,576)" in pilot[-1], pilot
    # issue 25: the total stays the budget (it jumped from 1,048,576 to 16,384 at the end),
    # and no rate (a stage reports in jumps: the pilot's first report read 2454267026it/s)
    assert "20480/20480" not in err and "20,480/20,480" not in err
    assert "it/s" not in err and "/s]" not in err
    assert "rejection: 100%" in err and "10/10" in err
