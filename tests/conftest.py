"""Settings shared by the whole suite.

Hypothesis runs derandomized: each property test draws the same examples on every run and
every machine, so the suite's verdict is reproducible (a CI failure can be re-run as it
was). ``HYPOTHESIS_PROFILE=explore`` draws fresh random examples, to search for new
counterexamples while developing.
"""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

settings.register_profile("scengen", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "scengen"))


#: The longest test files, longest first (their test times summed, from pytest's junit
#: report of ``make test`` on a loaded 2-core machine, session 6). ``--dist loadfile`` sends
#: whole files to the two workers in the order of the collection: these go first, so the
#: run ends on short files. xdist's own order (most tests first) put the files of one or
#: two long tests last (the schemathesis run, 170 s, one test): one worker then ran it alone
#: while the other had nothing left (~170 s of idle worker at the end of a 26-minute run).
#: A file missing here only runs later; a stale entry only matches nothing.
LONG_FIRST = (
    "tests/sampler/test_rare_bands.py",
    "tests/sampler/test_uncertainty.py",
    "tests/sampler/test_rare.py",
    "tests/app/test_schemathesis.py",
    "tests/browser/test_evaluation_browser.py",
    "tests/app/test_evaluations.py",
    "tests/app/test_evaluations_e2e.py",
    "tests/browser/test_dashboard_browser.py",
    "tests/app/test_dask.py",
    "tests/app/test_restart.py",
    "tests/sampler/test_sampling.py",
    "tests/sampler/test_subset.py",
    "tests/app/test_typed_boundaries.py",
    "tests/browser/test_dashboard_usability.py",
    "tests/sampler/test_campaign_ce.py",
    "tests/app/test_newcomer_cli.py",
    "tests/app/test_record_paths.py",
    "tests/app/test_evaluations_adapt.py",
    "tests/sampler/test_constraints.py",
    "tests/sampler/test_cli_sampler.py",
    "tests/app/test_worker_lifeline.py",
    "tests/app/test_rare_region_rates.py",
    "tests/app/test_export_delete_race.py",
    "tests/browser/test_dashboard_api_key.py",
    "tests/riskcore/test_sut.py",
    "tests/app/test_e2e_http.py",
)


def pytest_configure(config: pytest.Config) -> None:
    # xdist's --dist loadfile reorders files by their number of tests unless told not to
    # (its --no-loadscope-reorder): the collection's order below is the one wanted
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """``LONG_FIRST`` files first, in its order; the rest after them as collected (a
    stable sort: the tests of a file keep their order)."""
    rank = {name: i for i, name in enumerate(LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::", 1)[0], len(rank)))
