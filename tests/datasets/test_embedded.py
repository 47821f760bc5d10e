"""The embedded TNO data: present, licensed, loadable, and its table is sane."""

from __future__ import annotations

import numpy as np

from datasets.cutin_model import PARAM_NAMES
from datasets.egocentric import EGO_COLUMNS
from datasets.embedded import (
    DEFAULT_EVENTS_PATH,
    EMBEDDED_DIR,
    default_parameter_table,
    load_default_events,
)
from datasets.table import TABLE_COLUMNS


def test_embedded_files_are_small_and_licensed() -> None:
    assert DEFAULT_EVENTS_PATH.stat().st_size < 2_000_000
    licence = (EMBEDDED_DIR / "LICENSE").read_text()
    assert "MIT License" in licence and "ErwindeGelder" in licence
    prov = (EMBEDDED_DIR / "PROVENANCE.md").read_text()
    assert "627aa1e" in prov and "10.1109/ACCESS.2021.3136585" in prov


def test_default_events_shape() -> None:
    ev = load_default_events()
    assert list(ev.columns[: len(EGO_COLUMNS)]) == list(EGO_COLUMNS)
    n_events = ev["event_id"].nunique()
    assert 150 <= n_events <= 297
    # 10 Hz grid inside each event
    dt = ev.groupby("event_id")["t"].diff().dropna().to_numpy()
    assert np.allclose(dt, 0.1, atol=1e-6)
    # a copy each time: callers cannot damage the cache
    ev.loc[0, "ego_v"] = -1.0
    assert load_default_events().loc[0, "ego_v"] >= 0


def test_default_table_is_plausible() -> None:
    tb = default_parameter_table()
    assert list(tb.columns) == list(TABLE_COLUMNS)
    assert len(tb) >= 150
    assert tb["event_id"].is_unique
    assert np.isfinite(tb[list(PARAM_NAMES)].to_numpy()).all()
    # real highway cut-ins: speeds 8-40 m/s, lane changes 1-15 s long, gaps positive
    assert tb["v_ego"].between(8, 40).all()
    assert tb["p_v0"].between(5, 45).all()
    assert tb["p_t"].between(0.4, 8).all()
    assert (tb["gap"] > 0).all()
    # side agrees with the sign of p_y1
    assert ((tb["p_y1"] > 0) == (tb["side"] == "right")).all()
    # both sides occur (the source has 188 left and 109 right lane changes)
    assert set(tb["side"]) == {"left", "right"}
