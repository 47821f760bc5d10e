"""The CLI's contract: help works, unknown commands fail, user errors are one line."""

from __future__ import annotations

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
