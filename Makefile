# The two commands a newcomer needs:  make up   and   make test
# Everything else here is what those two call. Every Python package comes from the lock files in requirements/
# (exact versions + sha256 hashes), every npm package from package-lock.json; `make lock` refreshes them.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
TOOLS := .tools
UV := $(TOOLS)/bin/uv
# torch's CPU wheel is served from this directory on our machines (see requirements/pins.txt).
WHEELS := /opt/wheels
UV_INSTALL := $(UV) pip sync --quiet --python $(BIN)/python --require-hashes --find-links $(WHEELS)
UV_COMPILE := $(UV) pip compile --quiet --generate-hashes --python-version 3.11 \
	--python-platform x86_64-manylinux_2_28 --find-links $(WHEELS) --constraint requirements/pins.txt \
	$(if $(UPGRADE),--upgrade,)
RUNTIME_LOCK := requirements/runtime.txt
DEV_LOCK := requirements/dev.txt
HTMX := web/drem_web/static/vendor/htmx.min.js
# Country flags as images (emoji flags show as letters on Windows and in the test Chromium).
FLAGS := web/drem_web/static/vendor/flags/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Debian packages the tests and benches drive (apt pins them to the release's current, signed versions).
TEST_DEBS := chromium poppler-utils
BENCH_DEBS := wrk nginx-light

.PHONY: up demo test install install-test test-debs lock build bench clean-state

## make up: install everything, then start the local event stack on http://127.0.0.1:8000
up: install
	$(BIN)/drem up $(ARGS)

## make demo: the same stack with a demo event, sim cars driving sample models and a race director (fills the boards live)
demo: install
	$(BIN)/drem up --demo $(ARGS)

## make test: install the test dependencies (Python, npm htmx, Debian chromium), then run every test
test: install-test
	$(BIN)/python -m pytest $(PYTEST_ARGS)

install: $(VENV)/.installed-runtime $(HTMX) $(FLAGS)

install-test: $(VENV)/.installed-test $(HTMX) $(FLAGS) test-debs

$(UV):
	$(PYTHON) -m venv $(TOOLS)
	$(TOOLS)/bin/pip install --quiet --require-hashes -r requirements/tools.txt

$(VENV)/bin/python: | $(UV)
	$(UV) venv --quiet --python $(PYTHON) $(VENV)

# Sync makes the venv hold exactly the lock (nothing more), then drem itself goes in editable, without deps
# and without build isolation (its build backend comes from the lock too).
$(VENV)/.installed-runtime: $(RUNTIME_LOCK) pyproject.toml | $(VENV)/bin/python
	$(UV_INSTALL) $(RUNTIME_LOCK)
	$(UV) pip install --quiet --python $(BIN)/python --no-deps --no-build-isolation -e .
	rm -f $(VENV)/.installed-test
	touch $@

$(VENV)/.installed-test: $(DEV_LOCK) pyproject.toml | $(VENV)/bin/python
	$(UV_INSTALL) $(DEV_LOCK)
	$(UV) pip install --quiet --python $(BIN)/python --no-deps --no-build-isolation -e .
	rm -f $(VENV)/.installed-runtime
	touch $@

## make lock: re-resolve requirements/*.txt from pyproject.toml (keeps current pins; UPGRADE=1 takes the newest)
lock: | $(UV)
	$(UV_COMPILE) pyproject.toml requirements/build.in --all-extras -o $(DEV_LOCK)
	$(UV_COMPILE) pyproject.toml requirements/build.in --extra sim --extra car --constraint $(DEV_LOCK) \
		-o $(RUNTIME_LOCK)

node_modules/.package-lock.json: package.json package-lock.json
	npm ci --no-audit --no-fund
	touch $@

$(HTMX): node_modules/.package-lock.json
	mkdir -p $(dir $@)
	cp node_modules/htmx.org/dist/htmx.min.js $@

$(FLAGS): node_modules/.package-lock.json
	mkdir -p $(dir $@)
	cp node_modules/flag-icons/flags/4x3/*.svg $(dir $@)
	touch $@

# Installs only the Debian packages that are missing (dpkg knows), so a warm machine pays nothing.
test-debs:
	@$(call apt_install,$(TEST_DEBS))

define apt_install
missing=; for p in $(1); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
[ -z "$$missing" ] || { $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq $$missing; }
endef

## make build: vendor leaderboard/, web/ and the resource definition into functions/vendor for the Lambda bundle
build: install
	$(BIN)/drem build

## make bench: every bench/ script (each ends with a RESULT line); installs wrk and nginx for the spectator benches
bench: install-test
	@$(call apt_install,$(BENCH_DEBS))
	for b in bench/[!_]*.py; do $(BIN)/python $$b || exit 1; done

clean-state:
	rm -rf .drem
