"""One declared P(A) schema (app.schemas.PRegion) from the sampler's result to every
response that carries P(A) (issue 26 item 5)."""

from __future__ import annotations

import json
import math

from app.main import create_app
from app.schemas import PRegion
from sampler.methods import PRegion as SamplerPRegion
from tests.app.factories import make_settings


def test_every_p_region_in_the_api_is_the_one_schema(tmp_path: object) -> None:
    doc = create_app(make_settings(tmp_path)).openapi()  # type: ignore[arg-type]
    schemas = doc["components"]["schemas"]
    ref = "#/components/schemas/PRegion"

    def refs(schema: dict[str, object]) -> str:
        return json.dumps(schema["properties"]["p_region"])  # type: ignore[index]

    # before: POST /scenarios declared PRegion, the catalogue status and the dashboard's
    # shift view a free-form object
    for name in ("ScenariosResponse", "CatalogueStatus", "ShiftView"):
        match = [k for k in schemas if k.startswith(name)]
        assert match, name
        assert all(ref in refs(schemas[k]) for k in match), name


def test_the_schema_declares_the_sampler_s_fields() -> None:
    declared = set(PRegion.model_fields)
    assert set(SamplerPRegion.__dataclass_fields__) <= declared
    assert "ci" in declared


def test_a_stored_p_region_by_hand() -> None:
    stored = {"estimate": 0.001, "ci_low": 0.0009, "ci_high": 0.0011, "method": "mc",
              "n_draws": 4000, "n_hits": 4, "p_bounds": 0.99, "p_bounds_ci": [0.98, 1.0],
              "p_joint": "NaN", "mc_ci": [0.0008, 0.0012]}
    p = PRegion.model_validate(stored)
    assert p.ci == [0.0009, 0.0011]  # filled from its ends when stored without it
    assert p.n_hits == 4 and p.method == "mc" and p.p_joint is not None
    assert math.isnan(p.p_joint)
    out = json.loads(p.model_dump_json())
    assert out["p_joint"] == "NaN" and out["mc_ci"] == [0.0008, 0.0012]  # extras pass through
    assert out["cov"] is None
