"""One parser for the filters of the scenario and run listings (app.services.filters)."""

from __future__ import annotations

import pytest

from app.errors import InvalidInput
from app.services import catalogues, evaluations
from app.services.filters import parse_filters


def test_ranges_and_flags_by_hand() -> None:
    got = parse_filters([("btn_min", "0.5"), ("btn_max", "1"), ("a_max", "-2.5"),
                         ("collided", "TRUE"), ("ok", "0")], ("btn", "a"), ("collided", "ok"))
    assert got.ranges == (("btn", 0.5, 1.0), ("a", None, -2.5))
    assert got.flags == (("collided", True), ("ok", False))


@pytest.mark.parametrize("raw", ["inf", "-inf", "Infinity", "nan", "NaN", "x", ""])
@pytest.mark.parametrize("parse", [
    lambda items: catalogues.page_filter(items, where="query"),
    lambda items: evaluations.run_filter(
        [(k.replace("btn", "impact_speed"), v) for k, v in items], where="query"),
])
def test_a_bound_must_be_finite_in_both_listings(parse: object, raw: str) -> None:
    # the catalogue's listing took btn_max=inf (only isnan was checked) while the runs'
    # refused it; infinite values are stored as null, so such a bound never does what it says
    with pytest.raises(InvalidInput) as err:
        parse([("btn_max", raw)])  # type: ignore[operator]
    assert err.value.field in ("query.btn_max", "query.impact_speed_max")
    assert "finite number" in str(err.value)


def test_a_bound_is_read_in_ascii_digits_only() -> None:
    with pytest.raises(InvalidInput, match="ASCII digits"):
        evaluations.run_filter([("impact_speed_max", "1_0")])
    with pytest.raises(InvalidInput, match="ASCII digits"):
        evaluations.run_filter([("impact_speed_max", "\uff11")])


def test_unknown_names_list_the_listing_s_own_filters() -> None:
    with pytest.raises(InvalidInput) as err:
        catalogues.page_filter([("speed_min", "1")], where="--filter")
    assert err.value.field == "--filter.speed_min" and "and class" in str(err.value)
    with pytest.raises(InvalidInput) as err:
        evaluations.run_filter([("colided", "true")])
    assert err.value.field == "query.colided" and "and vs_careful" in str(err.value)
    with pytest.raises(InvalidInput) as err:
        parse_filters([("collided", "yes")], (), ("collided",))
    assert err.value.field == "query.collided"
