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

.PHONY: install install-run run test lint types pytest services bench clean qc-env

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# the service's dependencies only
$(RUN_STAMP): pyproject.toml | $(VENV)/bin/python
	$(PIP_ENV) $(BIN)/python -m pip install --quiet -e .
	touch $(RUN_STAMP)

# and the dev tools (pytest, ruff, mypy, playwright, ...)
$(STAMP): pyproject.toml | $(VENV)/bin/python
	$(PIP_ENV) $(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(RUN_STAMP) $(STAMP)

install-run: $(RUN_STAMP)

install: $(STAMP)

# host/port/store: SCENGEN_HOST, SCENGEN_PORT, SCENGEN_DATA_DIR (read by scengen serve)
run: install-run
	$(BIN)/scengen serve

# System services the tests talk to (PostgreSQL, Chromium): installed/started when absent.
services:
	bash scripts/ensure-services.sh

lint: install
	$(BIN)/ruff check .

types: install
	$(BIN)/mypy

pytest: install services
	$(BIN)/pytest -n 2 --dist loadfile $(PYTEST_ARGS)

test: lint types qc-env pytest

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
