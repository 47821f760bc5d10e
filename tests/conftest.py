"""Settings shared by the whole suite.

Hypothesis runs derandomized: each property test draws the same examples on every run and
every machine, so the suite's verdict is reproducible (a CI failure can be re-run as it
was). ``HYPOTHESIS_PROFILE=explore`` draws fresh random examples, to search for new
counterexamples while developing.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("scengen", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "scengen"))
