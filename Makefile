# Overseer: `make demo` runs the exporter with a simulated fleet; `make test` runs everything.
# On a machine without make, `./make demo` and `./make test` install it first (README, Quick start).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PYTEST_ARGS ?=
LOCK := requirements/lock.txt requirements/tools.txt
LINT_CHECKS := lint-ruff lint-format lint-mypy lint-imports lint-rules

.PHONY: setup system-deps demo test test-quick lint $(LINT_CHECKS) lock bench docs screenshot clean

setup: $(VENV)/.installed

# A fresh venv from the lock alone: the locked tools first (pip upgrades itself), then every locked
# distribution, hashes checked, then the package itself from this tree with nothing left to resolve;
# `pip check` proves the lock satisfies what the package and its extras ask for.
$(VENV)/.installed: pyproject.toml setup.py exporter/overseer/codec/_cstatus.c exporter/overseer/fleet/_cdeflate.c exporter/overseer/fleet/_cstamps.c $(LOCK)
	./scripts/install-system-deps base
	$(PYTHON) -m venv --clear $(VENV)
	$(BIN)/pip install --quiet --require-hashes -r requirements/tools.txt
	$(BIN)/pip install --quiet --require-hashes -r requirements/lock.txt
	$(BIN)/pip install --quiet --no-deps --no-build-isolation -e '.[test,ros2]'
	$(BIN)/pip check
	touch $@

system-deps:
	./scripts/install-system-deps test

demo: setup
	$(BIN)/overseer demo

# `make -k lint` runs every check even when one fails.
lint: $(LINT_CHECKS)

lint-ruff: setup
	$(BIN)/ruff check .

lint-format: setup
	$(BIN)/ruff format --check .

lint-mypy: setup
	$(BIN)/mypy

lint-imports: setup
	$(BIN)/lint-imports --no-logo

lint-rules: system-deps
	promtool check rules alert_rules/overseer.rules.yml alert_rules/overseer-fast.rules.yml
	promtool test rules alert_rules/overseer.rules.test.yml
	promtool check config deploy/prometheus/prometheus.yml deploy/prometheus/prometheus-fast.yml
	amtool check-config alert_rules/alertmanager.example.yml

# Every lint check, then the tests whatever lint said; fails if anything failed, and says what at the end.
test: setup system-deps
	@failed=""; for check in $(LINT_CHECKS); do $(MAKE) --no-print-directory $$check || failed="$$failed $$check"; done; \
	tests=0; $(BIN)/python -m pytest $(PYTEST_ARGS) || tests=$$?; \
	./scripts/test-verdict "$$tests" $$failed

# The unit and property tests: no server, no middleware, no browser (a couple of minutes).
test-quick: setup
	OVERSEER_TEST_QUICK=1 $(BIN)/python -m pytest -m "not servers" $(PYTEST_ARGS)

# Resolve the lock again after a change to pyproject.toml (other pins stay); `scripts/lock --upgrade`
# moves every pin to the newest release.
lock:
	./scripts/lock

bench: setup system-deps
	$(BIN)/python -m bench

# The configuration reference in docs/configuration.md, written from the config sections' option tables.
docs: setup
	$(BIN)/python -m overseer.config.reference docs/configuration.md

# The README's picture of the status page (docs/status-page.png), taken from `overseer demo` in Chromium.
screenshot: setup system-deps
	PYTHON=$(BIN)/python ./scripts/screenshot

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache build exporter/overseer/codec/*.so exporter/overseer/fleet/*.so
