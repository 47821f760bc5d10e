# Two entry points: `make run` and `make test`. Both create .venv and install the project.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
PYTEST_ARGS ?=

.PHONY: install run test lint types pytest services bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

run: install
	$(BIN)/scengen serve --host $${SCENGEN_HOST:-127.0.0.1} --port $${SCENGEN_PORT:-8000}

# System services the tests talk to (PostgreSQL, Chromium): installed/started when absent.
services:
	bash scripts/ensure-services.sh

lint: install
	$(BIN)/ruff check .

types: install
	$(BIN)/mypy

pytest: install services
	$(BIN)/pytest -n 2 --dist loadfile $(PYTEST_ARGS)

test: lint types pytest

bench: install
	for f in benchmarks/bench_*.py; do echo "== $$f"; $(BIN)/python $$f || exit 1; done

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache build *.egg-info
