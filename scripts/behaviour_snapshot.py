"""Record what a fixed set of CLI commands and HTTP requests answer, to prove a refactoring
changed no behaviour (issue 26: "record the outputs ... and check after every step that they
are bit-identical").

    .venv/bin/python scripts/behaviour_snapshot.py record  /tmp/before.json
    .venv/bin/python scripts/behaviour_snapshot.py compare /tmp/before.json

Each case's output is normalised (ids, timestamps, durations and paths removed) and
hashed with SHA-256; ``compare`` prints the cases whose hash changed and exits 1 if any
did. The store is a fresh temporary directory fitted with the quick test options of the
default model, so a run takes a few minutes.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import subprocess
import sys
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
SCENGEN = str(Path(sys.executable).parent / "scengen")

#: keys whose values differ from run to run by nature (wall clock, ids, paths)
VOLATILE = re.compile(r"(^|_)(id|ids|created|updated|started|finished|time_s|elapsed|"
                      r"seconds|duration_s|wall|path|data_dir|created_at|updated_at|"
                      r"timestamp|version|host|url|catalogue)$|_at$")
QUICK_MODEL = {"n_init": 1, "cv_folds": 2, "n_report_samples": 2000, "k_range": [1, 4]}


def _scrub(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _scrub(v) for k, v in value.items()
                if not VOLATILE.search(str(k)) and k not in {"elapsed_s", "timing"}}
    if isinstance(value, list):
        return [_scrub(v) for v in value]
    return value


DUMP = os.environ.get("SNAPSHOT_DUMP")  # a folder: also write each normalised text there
_n_dumped = 0


def _digest_text(text: str) -> str:
    """JSON (one document or JSON lines) is scrubbed before hashing; other text as is."""
    global _n_dumped
    lines = text.strip().splitlines()
    out = []
    for line in lines:
        try:
            out.append(json.dumps(_scrub(json.loads(line)), sort_keys=True))
        except ValueError:
            out.append(line)
    if len(out) > 1 and not all(o.startswith("{") for o in out):
        with contextlib.suppress(ValueError):  # one multi-line JSON document
            out = [json.dumps(_scrub(json.loads(text)), sort_keys=True)]
    if DUMP:
        _n_dumped += 1
        Path(DUMP).mkdir(parents=True, exist_ok=True)
        (Path(DUMP) / f"{_n_dumped:03d}.txt").write_text("\n".join(out))
    return hashlib.sha256("\n".join(out).encode()).hexdigest()


def _digest_zip(blob: bytes) -> str:
    h = hashlib.sha256()
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        for name in sorted(z.namelist()):
            data = z.read(name)
            text = data.decode("utf-8", "replace")
            # OpenSCENARIO headers carry the date; manifests carry ids and times
            text = re.sub(r'date="[^"]*"', 'date=""', text)
            text = re.sub(r"cat-[0-9a-f]{12}", "cat-", text)
            text = re.sub(r"<date>[^<]*</date>|<createdAt>[^<]*</createdAt>", "", text)
            h.update(re.sub(r"cat-[0-9a-f]{12}", "cat-", name).encode())
            if DUMP:
                (Path(DUMP) / "zip").mkdir(parents=True, exist_ok=True)
                (Path(DUMP) / "zip" / name).write_text(text)
            if name.endswith(".json"):
                h.update(_digest_text(text).encode())
            else:
                h.update(text.encode())
    return h.hexdigest()


def _cli(env: dict[str, str], *args: str) -> str:
    r = subprocess.run([SCENGEN, *args], env=env, capture_output=True, text=True, check=False,
                       cwd=ROOT)
    if r.returncode != 0:
        return f"exit {r.returncode}: {r.stderr.strip().splitlines()[-1:]}"
    return r.stdout


def cases(tmp: Path) -> dict[str, Callable[[], str]]:
    env = dict(os.environ, SCENGEN_DATA_DIR=str(tmp / "cli"), SCENGEN_LOCAL_WORKERS="0",
               SCENGEN_WARM_START="0", SCENGEN_DEFAULT_MODEL_OPTIONS=json.dumps(QUICK_MODEL))
    env.pop("SCENGEN_DATABASE_URL", None)
    summary = tmp / "summary.json"

    def cli_sample_summary() -> str:
        _cli(env, "sample", "-q", "-n", "20", "-c", "ttc<3", "--seed", "5",
             "--summary-json", str(summary), "-o", str(tmp / "s.jsonl"))
        return summary.read_text() + (tmp / "s.jsonl").read_text()

    def cli_catalogue() -> str:
        out = _cli(env, "catalogue", "create", "-q", "-n", "60", "--seed", "7", "-c", "ttc<3")
        m = re.search(r"cat-[0-9a-f]+", out)
        if not m:
            return "no id: " + out
        cid = m.group(0)
        parts = [_cli(env, "catalogue", "status", cid),
                 _cli(env, "catalogue", "scenarios", cid, "--limit", "10")]
        for fmt in ("csv", "jsonl"):
            f = tmp / f"c.{fmt}"
            _cli(env, "catalogue", "export", cid, "--format", fmt, "-o", str(f), "-q")
            parts.append(f.read_text() if f.exists() else "missing")
        f = tmp / "c.zip"
        _cli(env, "catalogue", "export", cid, "--format", "xosc", "-o", str(f), "-q")
        parts.append(_digest_zip(f.read_bytes()) if f.exists() else "missing")
        return "\n".join(_digest_text(p) for p in parts)

    out: dict[str, Callable[[], str]] = {
        "cli sample ttc<3 scored": lambda: _cli(
            env, "sample", "-q", "-n", "30", "-c", "ttc<3", "--seed", "3", "--score"),
        "cli sample mcmc ttc<2": lambda: _cli(
            env, "sample", "-q", "-n", "30", "-c", "ttc<2", "--seed", "1", "--sampler", "mcmc"),
        "cli sample subset-is ttc<1": lambda: _cli(
            env, "sample", "-q", "-n", "20", "-c", "ttc<1", "--seed", "2",
            "--sampler", "subset-is"),
        "cli sample btn>0.3": lambda: _cli(
            env, "sample", "-q", "-n", "10", "-c", "btn>0.3", "--seed", "2"),
        "cli sample whole model scenarios": lambda: _cli(
            env, "sample", "-q", "-n", "5", "--seed", "9", "--scenarios"),
        "cli sample summary + rates": cli_sample_summary,
        "cli risk example": lambda: _cli(env, "risk", "examples/cut-in.json"),
        "cli risk example summary": lambda: _cli(env, "risk", "examples/cut-in.json",
                                                 "--summary"),
        "cli catalogue create/status/export": cli_catalogue,
    }

    def http_cases() -> dict[str, str]:
        from fastapi.testclient import TestClient

        from app.main import create_app
        from app.settings import Settings

        settings = Settings(data_dir=tmp / "http", local_workers=0, chunk_size=5,
                            default_model_options=QUICK_MODEL, warm_start=False)
        res: dict[str, str] = {}
        with TestClient(create_app(settings)) as c:
            body = {"n": 20, "seed": 1, "constraints": ["ttc<3"], "score": True}
            res["http POST /scenarios scored"] = c.post("/scenarios", json=body).text
            body = {"n": 3, "seed": 4, "constraints": ["ttc<2"], "score": True,
                    "include_trajectories": True}
            res["http POST /scenarios trajectories"] = c.post("/scenarios", json=body).text
            ex = json.loads((ROOT / "examples" / "cut-in.json").read_text())
            res["http POST /risk"] = c.post("/risk", json=ex).text
            res["http GET /rates"] = c.get("/rates", params={"constraints": "ttc<3"}).text
            res["http GET /models/default"] = c.get("/models/default").text
            res["http bad constraint"] = c.post(
                "/scenarios", json={"n": 2, "constraints": ["ttc<<3"]}).text
            r = c.post("/catalogues", json={"n": 40, "seed": 7, "constraints": ["ttc<3"]})
            cid = r.json().get("id")
            for _ in range(600):
                s = c.get(f"/catalogues/{cid}").json()
                if s.get("status") in {"done", "failed"}:
                    break
                import time

                time.sleep(0.2)
            res["http catalogue status"] = c.get(f"/catalogues/{cid}").text
            res["http catalogue scenarios"] = c.get(f"/catalogues/{cid}/scenarios",
                                                    params={"limit": 10}).text
            res["http catalogue csv"] = c.get(f"/catalogues/{cid}/export",
                                              params={"format": "csv"}).text
            z = c.get(f"/catalogues/{cid}/export", params={"format": "commonroad"})
            res["http catalogue commonroad"] = (_digest_zip(z.content)
                                                if z.status_code == 200 else z.text)
        return res

    out["http"] = lambda: json.dumps({k: _digest_text(v) for k, v in http_cases().items()},
                                     sort_keys=True)
    return out


def run() -> dict[str, str]:
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        result: dict[str, str] = {}
        for name, fn in cases(tmp).items():
            text = fn()
            if name == "http":
                result.update({k: v for k, v in json.loads(text).items()})
            else:
                result[name] = _digest_text(text)
            print(f"  {name}", file=sys.stderr)
        return result


def main(argv: list[str]) -> int:
    if len(argv) != 3 or argv[1] not in {"record", "compare"}:
        print(__doc__, file=sys.stderr)
        return 2
    result = run()
    path = Path(argv[2])
    if argv[1] == "record":
        path.write_text(json.dumps(result, indent=1, sort_keys=True))
        print(f"recorded {len(result)} cases in {path}")
        return 0
    before = json.loads(path.read_text())
    changed = [k for k in sorted(set(before) | set(result)) if before.get(k) != result.get(k)]
    for k in changed:
        print(f"CHANGED: {k}")
    print(f"{len(result) - len(changed)} of {len(result)} cases identical")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
