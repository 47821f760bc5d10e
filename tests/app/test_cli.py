"""The CLI's contract: help works, unknown commands fail, user errors are one line."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.cli import main
from sampler import ConstraintError


def test_no_command_prints_help_and_fails(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    assert "usage: scengen" in capsys.readouterr().err


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert "scengen" in capsys.readouterr().out



@pytest.mark.parametrize(("exc", "code", "text"), [
    # the user's input (the one error tree under riskcore.FieldError): one line, exit 2
    (ConstraintError("constraints.0: unknown quantity 'foo'"), 2,
     "scengen: error: constraints.0: unknown quantity 'foo'\n"),
    # a library's ValueError is our bug: one line that says so, exit 70, no traceback
    (ValueError("array must not contain infs or NaNs"), 70,
     "scengen: internal error (please report it; SCENGEN_DEBUG=1 shows the trace): "
     "ValueError: array must not contain infs or NaNs\n"),
])
def test_user_errors_and_bugs_end_differently(monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str],
                                              exc: Exception, code: int, text: str) -> None:
    def handler(args: object) -> int:
        raise exc

    monkeypatch.delenv("SCENGEN_DEBUG", raising=False)
    monkeypatch.setattr("app.cli.data._describe", handler)  # `scengen data describe` runs it
    assert main(["data", "describe"]) == code
    assert capsys.readouterr().err == text


def test_the_lists_of_samplers_are_the_registry() -> None:
    """Issue 26 item 7: which samplers exist is written once, in ``sampler.methods.SAMPLERS``.
    The CLI's ``--sampler`` choices (written out so that the parser does not import the
    sampler), the API's enum, the catalogue check and the docs' usage line must name the
    same samplers in the same order; the dashboard offers a subset of them."""
    import re
    import typing
    from pathlib import Path

    from app.cli import build_parser
    from app.cli.options import SAMPLER_CHOICES
    from app.schemas import SamplingRequest
    from sampler import SAMPLER_NAMES
    from sampler.methods import SAMPLERS

    assert SAMPLER_NAMES == ("auto", "rejection", "mcmc", "subset", "subset-is")
    assert tuple(SAMPLERS) == SAMPLER_NAMES
    assert all(cls.name == name for name, cls in SAMPLERS.items())
    assert SAMPLER_CHOICES == SAMPLER_NAMES
    for argv in (["sample", "m.json"], ["catalogue", "create", "-n", "10"]):
        args = build_parser().parse_args([*argv, "--sampler", "subset-is"])
        assert args.sampler == "subset-is"
    field = SamplingRequest.model_fields["sampler"].annotation
    assert typing.get_args(field) == SAMPLER_NAMES
    root = Path(__file__).resolve().parents[2]
    usage = re.search(r"--sampler ([a-z|-]+)\]", (root / "docs/sampler.md").read_text())
    assert usage is not None and tuple(usage.group(1).split("|")) == SAMPLER_NAMES
    html = (root / "app/static/dashboard.html").read_text()
    offered = re.findall(r'<option value="([a-z-]+)">', html.split('id="sampler-select"')[1]
                         .split("</select>")[0])
    assert offered and set(offered) <= set(SAMPLER_NAMES)


def test_a_missing_file_is_named_in_words_not_errno(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 25 item 6: 'scengen risk' on a missing file printed a raw errno line."""
    from app.cli import main

    missing = tmp_path / "nope.json"
    assert main(["risk", str(missing), "--summary"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"scengen: error: {missing}: no such file"


def test_readable_summary_rounds_float_noise_only() -> None:
    """Issue 25 item 6: 'risk --summary' printed min_ttr 0.30000000000000004."""
    from app.cli.risk import readable

    assert readable({"min_ttr": 0.1 * 3, "x": [0.6000000000000001, 2], "s": "a",
                     "b": True, "tiny": 1.2345678901234567e-7}) == {
        "min_ttr": 0.3, "x": [0.6, 2], "s": "a", "b": True, "tiny": 1.23456789012e-7}
