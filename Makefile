# Two entry points: `make run` and `make test`. Both create .venv and install the project;
# `make run` only what the service needs, `make test` the dev tools as well.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
RUN_STAMP := $(VENV)/.installed-run-stamp
STAMP  := $(VENV)/.installed-stamp
PYTEST_ARGS ?=
# setuptools' notice that an editable install is one (the only build-backend message left)
PIP_ENV := PYTHONWARNINGS="ignore:Editable installation"
# exact versions of everything installed (see constraints.txt; `make lock` rewrites it)
LOCK   := constraints.txt

.PHONY: install install-run run test test-fast lint types pytest pytest-fast services bench clean qc-env lock

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# the service's dependencies only
$(RUN_STAMP): pyproject.toml $(LOCK) | $(VENV)/bin/python
	$(PIP_ENV) $(BIN)/python -m pip install --quiet -c $(LOCK) -e .
	touch $(RUN_STAMP)

# and the dev tools (pytest, ruff, mypy, playwright, ...)
$(STAMP): pyproject.toml $(LOCK) | $(VENV)/bin/python
	$(PIP_ENV) $(BIN)/python -m pip install --quiet -c $(LOCK) -e '.[dev]'
	touch $(RUN_STAMP) $(STAMP)

install-run: $(RUN_STAMP)

install: $(STAMP)

# After changing dependencies in pyproject.toml: upgrade everything within its ranges, then
# record the exact versions (the header comment of constraints.txt is kept).
lock: | $(VENV)/bin/python
	$(PIP_ENV) $(BIN)/python -m pip install --quiet --upgrade -e '.[dev]'
	{ sed -n '/^#/p' $(LOCK); $(BIN)/python -m pip freeze --exclude-editable; } > $(LOCK).new
	mv $(LOCK).new $(LOCK)
	touch $(RUN_STAMP) $(STAMP)

# host/port/store: SCENGEN_HOST, SCENGEN_PORT, SCENGEN_DATA_DIR (read by scengen serve)
# shared with others: SCENGEN_API_KEY=$$(openssl rand -hex 24) SCENGEN_HOST=0.0.0.0 make run
# (clients send the key in X-API-Key; SCENGEN_TRUSTED_HOSTS lists the names they use)
run: install-run
	$(BIN)/scengen serve

# System services the tests talk to (PostgreSQL, Chromium): installed/started when absent.
services:
	bash scripts/ensure-services.sh

lint: install
	$(BIN)/ruff check .
	$(BIN)/lint-imports --no-cache

types: install
	$(BIN)/mypy

pytest: install services
	$(BIN)/pytest -n 2 --dist loadfile $(PYTEST_ARGS)

# The fast loop: every test not marked slow, browser, postgres or esmini (the markers are in
# pyproject.toml; docs/architecture.md says what each means). Needs no system services.
FAST_MARKERS := not slow and not browser and not postgres and not esmini
pytest-fast: install
	$(BIN)/pytest -n 2 --dist loadfile -m "$(FAST_MARKERS)" $(PYTEST_ARGS)

# Both print their wall-clock time at the end (scripts/timed.sh).
test: install
	@bash scripts/timed.sh "make test" $(MAKE) --no-print-directory lint types qc-env pytest

test-fast: install
	@bash scripts/timed.sh "make test-fast" $(MAKE) --no-print-directory lint types pytest-fast

# The ASAM Quality Checker (tests/app/test_exports_qc.py) in its own environment: its
# numpy < 2 pin must not touch .venv.
QC_VENV  := .venv-qc
QC_STAMP := $(QC_VENV)/.installed-stamp

$(QC_STAMP): scripts/qc-requirements.txt
	test -x $(QC_VENV)/bin/python || $(PYTHON) -m venv $(QC_VENV)
	$(QC_VENV)/bin/python -m pip install --quiet -r scripts/qc-requirements.txt
	touch $(QC_STAMP)

qc-env: $(QC_STAMP)

bench: install
	for f in benchmarks/bench_*.py; do echo "== $$f"; $(BIN)/python $$f || exit 1; done

clean:
	rm -rf $(VENV) $(QC_VENV) .mypy_cache .ruff_cache .pytest_cache build *.egg-info
