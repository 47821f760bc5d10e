"""Finding 7 of issue 27: a binary quantity meaning "collides" is sampled through its
continuous twin, so ``r157_collision>0.5`` gives the P(A) of ``r157_impact_speed>0``
(before: "levels did not converge" after 10 s on the default model)."""

from __future__ import annotations

from pathlib import Path

import pytest

from app import domain
from sampler import Constraint


@pytest.mark.parametrize(("text", "twin"), [
    ("r157_collision>0.5", True), ("r157_collision>0", True), ("r157_collision>=1", True),
    ("r157_collision>=0.01", True), ("r157_collision>1", False),
    ("r157_collision>=0", False), ("r157_collision<0.5", False), ("ttc<3", False),
])
def test_which_constraints_become_their_twin(text: str, twin: bool) -> None:
    (got,) = domain.parse_constraints([text])
    if twin:
        assert got == Constraint(name="r157_impact_speed", op=">", value=0.0)
    else:
        assert got.name == text.split("<")[0].split(">")[0]


@pytest.mark.slow
def test_a_collision_region_has_the_p_a_of_its_impact_speed_twin(model_cache_dir: Path,
                                                                tmp_path: Path) -> None:
    from app.services.store import open_context
    from tests.app.factories import copy_model_cache, make_settings

    copy_model_cache(model_cache_dir, tmp_path)
    ctx = open_context(make_settings(tmp_path))
    try:
        model = ctx.model(ctx.default_model_id)
        binary = domain.estimate_region(model, domain.parse_constraints(
            ["r157_collision>0.5"]), 7)
        twin = domain.estimate_region(model, domain.parse_constraints(
            ["r157_impact_speed>0"]), 7)
        assert binary == twin and 0 < binary["estimate"] < 1e-3
    finally:
        ctx.close()
