"""Run the ASAM Quality Checker bundles on OpenSCENARIO / OpenDRIVE files; print JSON.

Runs in the quality-checker environment (``make qc-env`` makes ``.venv-qc`` with
``asam-qc-openscenarioxml``, ``asam-qc-opendrive`` and their framework; they pin numpy < 2,
so they cannot live in the project's ``.venv``)::

    .venv-qc/bin/python scripts/qc_check.py FILE.xosc FILE.xodr ...

For every file: the checker bundle (``qc_openscenario`` for ``.xosc``, ``qc_opendrive``
for ``.xodr``) runs with a generated configuration; the printed JSON maps each file to
``{"checkers": {checker_id: status}, "issues": [{"level", "checker", "rule",
"description"}]}``, level ``error``, ``warning`` or ``information``. Exit status 0 when the
checks ran (whatever they found), 2 on bad arguments, 1 when a bundle failed to run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

from qc_baselib import Result  # type: ignore[import-not-found]

BUNDLES = {".xosc": ("qc_openscenario", "xoscBundle"), ".xodr": ("qc_opendrive", "xodrBundle")}
LEVELS = {1: "error", 2: "warning", 3: "information"}


def check(path: Path, work: Path) -> dict[str, object]:
    command, bundle = BUNDLES[path.suffix]
    result_file = work / f"{path.stem}.{bundle}.xqar"
    config = work / f"{path.stem}.{bundle}.config.xml"
    config.write_text(
        "<?xml version='1.0' encoding='UTF-8'?>\n<Config>\n"
        f'  <Param name="InputFile" value="{path.resolve()}"/>\n'
        f'  <CheckerBundle application="{bundle}">\n'
        f'    <Param name="resultFile" value="{result_file}"/>\n'
        "  </CheckerBundle>\n</Config>\n", encoding="utf-8")
    exe = Path(sys.executable).with_name(command)
    proc = subprocess.run([str(exe), "-c", str(config)], cwd=work, capture_output=True,
                          text=True, check=False)
    if proc.returncode != 0 or not result_file.exists():
        raise RuntimeError(f"{command} failed on {path}: {proc.stderr[-2000:]}")
    result = Result()
    result.load_from_file(str(result_file))
    checkers: dict[str, str] = {}
    issues: list[dict[str, str]] = []
    for checker in result.get_checker_results(bundle):
        status = checker.status
        checkers[checker.checker_id] = str(getattr(status, "value", status))
        for issue in checker.issues:
            issues.append({"level": LEVELS.get(int(issue.level), str(issue.level)),
                           "checker": checker.checker_id, "rule": issue.rule_uid,
                           "description": issue.description})
    return {"checkers": checkers, "issues": issues}


def main(argv: list[str]) -> int:
    paths = [Path(a) for a in argv]
    bad = [str(p) for p in paths if p.suffix not in BUNDLES or not p.is_file()]
    if not paths or bad:
        print(f"usage: qc_check.py FILE.xosc|FILE.xodr ...; not a checkable file: "
              f"{', '.join(bad) or '(none given)'}", file=sys.stderr)
        return 2
    out: dict[str, object] = {}
    with tempfile.TemporaryDirectory(prefix="qc-") as tmp:
        try:
            for path in paths:
                out[str(path)] = check(path, Path(tmp))
        except RuntimeError as exc:
            print(str(exc), file=sys.stderr)
            return 1
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
