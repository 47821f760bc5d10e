"""Issue 14 item 8: the docs speak to users (no files they lack, no issue numbers), the
example scenario in the repository works with `scengen risk` and `POST /risk`, and
`convert-tno` cannot overwrite the packaged data by accident."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from app.cli import main

ROOT = Path(__file__).resolve().parents[2]
USER_DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
EXAMPLE = ROOT / "examples" / "cut-in.json"
TOP = ("app", "datasets", "docs", "examples", "riskcore", "sampler", "scripts", "tests",
       "benchmarks")


@pytest.mark.parametrize("doc", USER_DOCS, ids=lambda p: p.name)
def test_docs_name_no_files_the_user_lacks(doc: Path) -> None:
    text = doc.read_text(encoding="utf-8")
    assert "../shared" not in text
    assert "DESIGN.md" not in text
    assert not re.search(r"\(issues? \d", text), "internal issue numbers"
    for path in re.findall(r"`([A-Za-z0-9_.-]+(?:/[A-Za-z0-9_.-]+)+)`", text):
        if path.split("/")[0] in TOP:
            assert (ROOT / path).exists(), f"{doc.name} names {path}, which is not there"


def test_the_example_scenario_scores_on_the_command_line(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["risk", str(EXAMPLE), "--summary"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert 0.0 <= summary["risk"] <= 1.0
    assert summary["min_ttc"] is not None  # the cutter closes in (TTC 3.6 s at the cut-in)


def test_the_example_scenario_scores_over_http(client: Any) -> None:
    r = client.post("/risk", content=EXAMPLE.read_bytes(),
                    headers={"content-type": "application/json"})
    assert r.status_code == 200, r.text
    assert set(r.json()["summary"]) >= {"risk", "min_ttr"}


def test_convert_tno_needs_an_output_and_keeps_the_packaged_data(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from datasets.embedded import DEFAULT_EVENTS_PATH

    before = DEFAULT_EVENTS_PATH.read_bytes()
    src = tmp_path / "cut-in.json"
    src.write_text("{}")
    with pytest.raises(SystemExit) as info:
        main(["data", "convert-tno", "--input", str(src)])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "-o/--out" in err and err.count("\n") == 1
    assert main(["data", "convert-tno", "--input", str(src), "-o",
                 str(DEFAULT_EVENTS_PATH)]) == 2
    assert "--replace-embedded" in capsys.readouterr().err
    assert DEFAULT_EVENTS_PATH.read_bytes() == before


def test_the_readme_lists_every_doc_and_the_dashboards_views() -> None:
    """Issue 25: the README's docs table left out docs/criticality.md and its dashboard
    paragraph described views that no longer exist (evasion types, minimum TTR)."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    table = readme[readme.index("### Documentation"):]
    for doc in sorted((ROOT / "docs").glob("*.md")):
        assert f"| `docs/{doc.name}` |" in table, doc.name
    page = (ROOT / "app" / "static" / "dashboard.html").read_text(encoding="utf-8")
    views = re.findall(r'<a href="#view-[a-z]+">(\d) ([^<]+)</a>', page)
    assert len(views) == 7
    section = " ".join(readme[readme.index("### Dashboard"):
                              readme.index("### Command line")].split())
    for number, name in views:
        assert f"**{number} {name}**" in section, name
    assert "evasion types" not in section and "minimum TTR" not in section
