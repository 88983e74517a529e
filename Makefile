# Overseer: `make demo` runs the exporter with a simulated fleet; `make test` runs everything.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PYTEST_ARGS ?=

.PHONY: setup system-deps demo test test-quick lint bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml setup.py exporter/overseer/codec/_cstatus.c
	./scripts/install-system-deps base
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $@

system-deps:
	./scripts/install-system-deps test

demo: setup
	$(BIN)/overseer demo

lint: setup system-deps
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/lint-imports --no-logo
	promtool check rules alert_rules/overseer.rules.yml alert_rules/overseer-fast.rules.yml
	promtool test rules alert_rules/overseer.rules.test.yml
	promtool check config deploy/prometheus/prometheus.yml deploy/prometheus/prometheus-fast.yml
	amtool check-config alert_rules/alertmanager.example.yml

test: setup system-deps lint
	$(BIN)/python -m pytest $(PYTEST_ARGS)

# The unit and property tests: no server, no middleware, no browser (a couple of minutes).
test-quick: setup
	OVERSEER_TEST_QUICK=1 $(BIN)/python -m pytest -m "not servers" $(PYTEST_ARGS)

bench: setup system-deps
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache build exporter/overseer/codec/*.so
