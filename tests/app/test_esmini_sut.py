"""A system under test driving the ego inside esmini (app.esmini).

Without esmini: the adapter's box test on hand-computed cases, how it finds the library,
the stop trigger of the file it runs (the vehicle model and the band geometry are
riskcore.sut's: tests/riskcore/test_sut_vehicle.py). With esmini's library
(``$SCENGEN_ESMINI_LIB``, else ../shared/tools/esmini/lib/libesminiLib.so next to the
checkout; the tests marked ``esmini`` skip without it):

* the adapter's bookkeeping is scengen's: scengen's simulator run on the world esmini played
  (``esmini_world``: the cutter's states as esmini reported them) gives the same runs to
  1e-9, for SUTs that collide, brake on a TTC gate or at an interpolated moment, with a
  perception delay and an update period;
* the same SUT on the same cut-ins in both simulators: the same collision verdicts and
  smallest gaps within 0.1 m (4 cut-ins here; 200 in the slow test and
  scripts/esmini_sut_agreement.py).
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import math
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from app.esmini import (
    ENV_VAR,
    EsminiError,
    VehicleState,
    adapter_document,
    boxes_touch,
    esmini_world,
    find_library,
    simulate_esmini,
)
from app.exports import build_manifest, export_catalogue
from riskcore import FieldError
from riskcore.scenario import ConcreteScenario
from riskcore.sut import (
    RUN_FIELDS,
    CutInBatch,
    Observation,
    RunBatch,
    SimSettings,
    make_sut,
    per_run,
    simulate,
)
from sampler.scenario.builder import build_scenario
from tests.app.esmini_run import CUTIN_PARAMS, cutins

REPO = Path(__file__).resolve().parents[2]
SHARED_LIB = REPO.parent / "shared" / "tools" / "esmini" / "lib" / "libesminiLib.so"

GAP_TOL = 0.1  # m, issue 24 item 11
EXACT = 1e-9


# ------------------------------------------------------------------------- geometry


def test_boxes_touch_hand_computed() -> None:
    # ego 4.5 m x 1.8 m at the origin; a car of the same size straight ahead
    ahead = VehicleState(4.6, 0.0, 0.0, 20.0, 0.0)
    assert not boxes_touch(ahead, 0.0, 0.0, 2.25, 0.9, 2.25, 0.9)  # 0.1 m gap
    assert boxes_touch(VehicleState(4.4, 0.0, 0.0, 20.0, 0.0), 0.0, 0.0, 2.25, 0.9, 2.25,
                       0.9)
    # beside: lateral gap 0.1 m
    assert not boxes_touch(VehicleState(0.0, 1.9, 0.0, 20.0, 0.0), 0.0, 0.0, 2.25, 0.9, 2.25,
                           0.9)
    # turned by 10° with its rear-right corner just inside the ego's front-left
    h = math.radians(10.0)
    cx = 2.25 + 2.25 * math.cos(h) - 0.9 * math.sin(h) - 0.05
    cy = 0.9 + 2.25 * math.sin(h) + 0.9 * math.cos(h) - 0.05
    assert boxes_touch(VehicleState(cx, cy, h, 20.0, 0.0), 0.0, 0.0, 2.25, 0.9, 2.25, 0.9)
    assert not boxes_touch(VehicleState(cx + 0.1, cy + 0.1, h, 20.0, 0.0), 0.0, 0.0, 2.25,
                           0.9, 2.25, 0.9)


# -------------------------------------------------------------------- the library


def test_no_library_is_a_field_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv(ENV_VAR, raising=False)
    with pytest.raises(EsminiError, match=ENV_VAR) as err:
        find_library()
    assert err.value.field == "library" and isinstance(err.value, FieldError)
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "nope.so"))
    with pytest.raises(EsminiError, match="is not a file"):
        find_library()
    not_a_library = tmp_path / "libfake.so"
    not_a_library.write_text("not ELF")
    scenario = build_scenario(CUTIN_PARAMS[0], seed=0)
    with pytest.raises(EsminiError, match="does not load") as err:
        simulate_esmini(make_sut("none"), [scenario], seeds=0, library=not_a_library)
    assert err.value.field == "library"
    monkeypatch.setenv(ENV_VAR, str(not_a_library))
    assert find_library() == not_a_library.resolve()


def _schema() -> etree.XMLSchema:
    files = importlib.metadata.files("scenariogeneration") or []
    [path] = [f for f in files if f.name == "OpenSCENARIO_1_2.xsd"]
    return etree.XMLSchema(etree.parse(str(path.locate())))


def test_the_adapter_runs_the_test_file_without_its_conflict_over_stop(tmp_path: Path) -> None:
    manifest = build_manifest(seed=0, model_hash=None, sampler_settings={}, constraints=[],
                              p_region=None)
    zpath = export_catalogue("xosc", [(build_scenario(CUTIN_PARAMS[0], seed=0), {})], manifest,
                             tmp_path / "c.zip", mode="test")
    with zipfile.ZipFile(zpath) as zf:
        exported = zf.read("scenario_0000000.xosc")
    stop = "/OpenSCENARIO/Storyboard/StopTrigger/ConditionGroup"
    before = etree.fromstring(exported).xpath(stop)
    # collision, four ways of an over conflict, the time limit
    assert len(before) == 6
    doc = etree.fromstring(adapter_document(exported))
    after = doc.xpath(stop)
    assert len(after) == 2
    assert after[0].xpath(".//CollisionCondition/EntityRef/@entityRef") == ["cutter"]
    assert [c.get("name") for c in after[1].findall("Condition")] == ["time limit"]
    assert _schema().validate(doc), _schema().error_log
    # nothing else changed
    for group in before[1:5]:
        group.getparent().remove(group)
    assert etree.tostring(before[0].getroottree()) == etree.tostring(doc.getroottree())


# --------------------------------------------------------------------- with esmini


@pytest.fixture(scope="module")
def library() -> Path:
    value = os.environ.get(ENV_VAR)
    path = Path(value) if value else SHARED_LIB
    if not path.is_file():
        pytest.skip(f"esmini's library not found: set {ENV_VAR} to libesminiLib.so "
                    "(see shared/tools/esmini/README.md)")
    return path


def _scenarios() -> list[ConcreteScenario]:
    return cutins(CUTIN_PARAMS)


def _same_runs(a: RunBatch, b: RunBatch, tol: float) -> None:
    for name, spec in RUN_FIELDS.items():
        x, y = getattr(a, name), getattr(b, name)
        if spec.kind != "float":
            assert list(x) == list(y), name
            continue
        assert np.array_equal(np.isnan(x), np.isnan(y)), name
        assert np.array_equal(np.isinf(x), np.isinf(y)), name
        fin = np.isfinite(x)
        assert np.all(np.abs(x[fin] - y[fin]) <= tol), (name, x, y)


@pytest.mark.esmini
@pytest.mark.parametrize(("sut", "settings"), [
    ("none", SimSettings()),  # every closing cut-in collides
    ("acc_aeb", SimSettings()),  # a TTC gate
    ("r157_cc", SimSettings()),  # braking at an interpolated moment (command_onset)
    ("idm", SimSettings(perception_delay=0.2, update_period=0.05)),
    ("rss", SimSettings(dt=0.02)),
])
def test_the_adapter_is_scengens_simulator_on_the_world_esmini_played(
        library: Path, sut: str, settings: SimSettings) -> None:
    scenarios = _scenarios()
    res = simulate_esmini(make_sut(sut), scenarios, seeds=5, settings=settings,
                          library=library, profiles=True)
    assert res.runs.profiles is not None
    world = esmini_world(CutInBatch.from_scenarios(scenarios), res.runs.profiles)
    ours = simulate(make_sut(sut), world, seeds=5, settings=settings)
    _same_runs(ours, res.runs, EXACT)
    # esmini moved the ego where the vehicle model put it; its collision flag is the box test
    assert res.diagnostics.ego_drift.max() < 1e-9
    assert res.diagnostics.flag_box_disagree.sum() == 0
    if sut == "none":
        assert res.runs.collided.sum() == 3  # the comparison covers contact
    else:
        assert res.runs.max_decel.max() > 5.0  # and braking


@pytest.mark.esmini
@pytest.mark.parametrize("sut", ["none", "idm", "acc_aeb", "r157_cc", "rss"])
def test_same_verdicts_and_gaps_as_scengens_simulator(library: Path, sut: str) -> None:
    scenarios = _scenarios()
    ours = simulate(make_sut(sut), CutInBatch.from_scenarios(scenarios), seeds=1)
    theirs = simulate_esmini(make_sut(sut), scenarios, seeds=1, library=library).runs
    assert list(theirs.collided) == list(ours.collided)
    free = ~ours.collided
    assert np.all(np.abs(theirs.min_gap[free] - ours.min_gap[free]) <= GAP_TOL)
    hit = ours.collided
    assert np.all(np.abs(theirs.t_contact[hit] - ours.t_contact[hit]) <= 1e-3)
    assert list(theirs.end) == list(ours.end)


@pytest.mark.esmini
def test_the_cutter_is_found_by_its_name_or_as_the_first_object(library: Path) -> None:
    scenarios = _scenarios()[:2]
    renamed = [dataclasses.replace(s, objects=(dataclasses.replace(s.objects[0], id="car 7"),))
               for s in scenarios]
    ours = simulate_esmini(make_sut("acc_aeb"), scenarios, seeds=2, library=library).runs
    theirs = simulate_esmini(make_sut("acc_aeb"), renamed, seeds=2, library=library).runs
    _same_runs(ours, theirs, 0.0)


class _Creep:
    """Accelerates gently for ever (0.15 m/s², above the 0.1 m/s² of 'settled')."""

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: Observation) -> float:
        return 0.15


@pytest.mark.esmini
def test_a_run_that_never_resolves_ends_at_the_exports_time_limit(library: Path) -> None:
    # a cutter 5 m/s faster pulls away in front of an ego that keeps speeding up: the
    # conflict never settles; esmini's own stop trigger ends the run at the export's time
    # limit, the scenario's duration + 30 s (scengen's own simulator goes on, up to t_max:
    # there the never-braking ego hits the cutter at 66 s)
    s = build_scenario({"p_y1": 0.05, "p_t": 1.5, "p_a1": 0.0, "p_a2": 0.0, "p_a3": 0.0,
                        "p_v0": 31.0, "dv": -5.0, "gap": 20.0}, seed=0)
    duration = float(s.t[-1] - s.t[0])
    runs = simulate_esmini(per_run(_Creep, "creep"), [s], seeds=0, library=library).runs
    assert list(runs.end) == ["esmini_stop"]
    assert runs.end_time[0] == pytest.approx(duration + 30.0, abs=0.011)
    ours = simulate(per_run(_Creep, "creep"), CutInBatch.from_scenarios([s]), seeds=0)
    assert ours.end_time[0] > duration + 31.0


class _Recorder:
    """A plain per-run SUT: keeps its speed until the gap is below 10 m, then brakes;
    records the seed it was given."""

    seeds: list[int] = []  # noqa: RUF012 - shared on purpose

    def reset(self, seed: int) -> None:
        _Recorder.seeds.append(seed)

    def act(self, obs: Observation) -> float:
        ahead = obs.present[0] and obs.lane[0] == 0 and obs.dx[0] > 0
        return -6.0 if ahead and obs.gap[0] < 10.0 else 0.0


@pytest.mark.esmini
def test_a_per_run_sut_gets_the_seeds_scengen_gives_it(library: Path) -> None:
    scenarios = _scenarios()
    _Recorder.seeds = []
    ours = simulate(per_run(_Recorder, "rec"), CutInBatch.from_scenarios(scenarios), seeds=9)
    seeds_scengen = list(_Recorder.seeds)
    _Recorder.seeds = []
    theirs = simulate_esmini(per_run(_Recorder, "rec"), scenarios, seeds=9,
                             library=library).runs
    assert _Recorder.seeds == seeds_scengen and len(set(seeds_scengen)) == len(scenarios)
    assert list(theirs.collided) == list(ours.collided)
    assert theirs.sut == "rec"
    assert np.nanmax(np.abs(theirs.t_brake_rel_tp - ours.t_brake_rel_tp)) <= 0.011


@pytest.mark.esmini
def test_a_sut_that_returns_nonsense_is_named(library: Path) -> None:
    class Bad:
        def reset(self, seed: int) -> None:
            pass

        def act(self, obs: Observation) -> float:
            return math.nan

    with pytest.raises(EsminiError, match=r"bad\.act") as err:
        simulate_esmini(per_run(Bad, "bad"), _scenarios()[:1], seeds=0, library=library)
    assert err.value.field == "sut"


# ------------------------------------------------- 200 cut-ins of the default model


@pytest.fixture(scope="module")
def default_200() -> list[ConcreteScenario]:
    """The same 200 ttc<3 cut-ins of the default model (seed 7) for the three tests below:
    fitted and drawn once (each test only reads them; ConcreteScenario is frozen)."""
    from datasets import default_parameter_table
    from sampler import CutInGMM, sample

    model = CutInGMM(random_state=0).fit(default_parameter_table())
    return list(sample(model, ["ttc<3"], n=200, seed=7, method="rejection").scenarios())


@pytest.mark.esmini
@pytest.mark.slow
@pytest.mark.parametrize(("sut", "beyond"), [("acc", 0), ("r157_cc", 2)])
def test_200_cut_ins_agree_with_scengens_simulator(library: Path, sut: str, beyond: int,
                                                   default_200: list[ConcreteScenario]
                                                   ) -> None:
    """Issue 24 item 11: the same SUT on the same 200 ttc<3 cut-ins of the default model:
    collision verdicts agree on >= 99 % (measured: all); smallest gaps within 0.1 m except
    ``beyond`` runs (measured: r157_cc's TTC gate in 1 of 197 runs without contact, by
    0.12 m; docs/systems.md explains it and acc_aeb's and rss's), none beyond 0.15 m;
    and every difference is the
    cutter's motion as esmini plays it: scengen's simulator on esmini's world reproduces
    esmini's runs."""
    scenarios = default_200
    batch = CutInBatch.from_scenarios(scenarios)
    ours = simulate(make_sut(sut), batch, seeds=7)
    res = simulate_esmini(make_sut(sut), scenarios, seeds=7, library=library, profiles=True)
    theirs = res.runs
    agree = int((ours.collided == theirs.collided).sum())
    assert agree >= 198
    free = ~ours.collided & ~theirs.collided
    both_inf = np.isinf(ours.min_gap) & np.isinf(theirs.min_gap)
    diff = np.where(both_inf, 0.0, np.abs(ours.min_gap - theirs.min_gap))[free]
    assert int((diff > GAP_TOL).sum()) <= beyond
    assert diff.max() <= 0.15
    assert theirs.profiles is not None
    world = simulate(make_sut(sut), esmini_world(batch, theirs.profiles), seeds=7)
    _same_runs(world, theirs, 1e-6)


@pytest.mark.esmini
@pytest.mark.slow
def test_acc_aeb_gap_difference_is_the_ttc_threshold_grazed(
        library: Path, default_200: list[ConcreteScenario]) -> None:
    """The largest smallest-gap difference of the 200 cut-ins with acc_aeb is the TTC
    grazing the AEB's 1.5 s (docs/systems.md: run 65, 2.41 m in scengen, 3.79 m in esmini,
    on the machine it was measured on): the TTC comes down to the threshold and turns
    back. With the cutter's speed interpolated (scengen) it stays above 1.5 s and the AEB
    never fires; with esmini's speed, constant along each 0.1 s segment, it dips below
    1.5 s at the end of a segment and the AEB (9 m/s²) fires. Fails if the difference has
    another cause (the AEB firing in both or in neither, or a TTC far from the threshold).

    The run is found, not named: the 200 draws differ between processors in their last
    bits, so which run grazes (if any) depends on the machine. Where none does, every
    verdict agrees and every smallest gap within 0.15 m (checked): nothing to explain."""
    scenarios = default_200
    whole = CutInBatch.from_scenarios(scenarios)
    all_ours = simulate(make_sut("acc_aeb"), whole, seeds=7)
    all_theirs = simulate_esmini(make_sut("acc_aeb"), scenarios, seeds=7,
                                 library=library).runs
    assert bool(np.all(all_ours.collided == all_theirs.collided))
    both_inf = np.isinf(all_ours.min_gap) & np.isinf(all_theirs.min_gap)
    gaps = np.where(both_inf, 0.0, all_theirs.min_gap - all_ours.min_gap)
    run = int(np.argmax(np.abs(gaps)))
    if abs(gaps[run]) <= 0.15:
        # no run grazes the threshold on this machine: every verdict agrees (above) and
        # every smallest gap within 0.15 m, the bound of the 200-run test above (a
        # one-step difference of the AEB's onset, as acc_aeb's run 54 in docs/systems.md)
        return
    batch = CutInBatch.from_scenarios(scenarios).subset(np.array([run]))
    ours = simulate(make_sut("acc_aeb"), batch, seeds=7, profiles=True, engine="loop")
    res = simulate_esmini(make_sut("acc_aeb"), [scenarios[run]], seeds=7, library=library,
                          profiles=True)
    theirs = res.runs
    assert ours.profiles is not None and theirs.profiles is not None
    assert theirs.min_gap[0] - ours.min_gap[0] > 1.0
    half = 0.5 * (batch.ego_length + float(batch.c_length[0]))
    pe = theirs.profiles
    n = int(np.sum(np.isfinite(pe["x"][0])))
    vx_e = pe["cv"][0, :n] * np.cos(pe["cpsi"][0, :n])
    clos_e = pe["v"][0, :n] - vx_e
    ttc_e = np.where(clos_e > 0, (pe["cx"][0, :n] - pe["x"][0, :n] - half)
                     / np.where(clos_e > 0, clos_e, 1.0), np.inf)
    po = ours.profiles
    t = np.asarray(po["t"])[:n]
    cx_o = np.interp(t, batch.t, batch.cx[0])
    vx_o = np.interp(t, batch.t, batch.cv[0] * np.cos(batch.cpsi[0]))
    clos_o = po["v"][0, :n] - vx_o
    ttc_o = np.where(clos_o > 0, (cx_o - po["x"][0, :n] - half)
                     / np.where(clos_o > 0, clos_o, 1.0), np.inf)
    # scengen: the AEB never fires, the TTC's minimum just above the threshold
    assert np.nanmin(po["a"][0]) > -3.0
    assert 1.5 < ttc_o.min() < 1.505
    # esmini: the AEB fires, at a TTC just below the threshold at a segment's end
    k = int(np.argmax(ttc_e < 1.5))
    assert ttc_e[k] < 1.5 and ttc_e.min() > 1.495
    assert np.isclose(t[k] * 10.0, round(t[k] * 10.0), atol=1e-6)
    assert np.nanmin(pe["a"][0]) < -8.0
    # the positions are the same up to there; the cutter's speed is not
    assert np.max(np.abs(pe["x"][0, :k + 1] - po["x"][0, :k + 1])) < 1e-3
    assert np.max(np.abs(pe["cx"][0, :k + 1] - cx_o[:k + 1])) < 1e-3
    assert abs(vx_e[k] - vx_o[k]) > 0.003
