# The two commands a newcomer needs:  make up   and   make test
# Everything else here is what those two call.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
HTMX := web/drem_web/static/vendor/htmx.min.js
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: up demo test install install-test build bench clean-state

## make up: install everything, then start the local event stack on http://127.0.0.1:8000
up: install
	$(BIN)/drem up $(ARGS)

## make demo: the same stack with a demo event, sim cars driving sample models and a race director (fills the boards live)
demo: install
	$(BIN)/drem up --demo $(ARGS)

## make test: install the test dependencies (Python, npm htmx, Debian chromium), then run every test
test: install-test
	$(BIN)/python -m pytest $(PYTEST_ARGS)

install: $(VENV)/.installed-runtime $(HTMX)

install-test: install $(VENV)/.installed-test /usr/bin/chromium

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q "pip<26.3"

$(VENV)/.installed-runtime: pyproject.toml | $(VENV)/bin/python
	$(BIN)/pip install -q -e ".[sim,car]"
	touch $@

# torch==2.13.0 is the CPU wheel on our machines (see pyproject's train extra).
$(VENV)/.installed-test: pyproject.toml $(VENV)/.installed-runtime
	$(BIN)/pip install -q -e ".[sim,car,train,infra,dev]"
	touch $@

node_modules/htmx.org/dist/htmx.min.js: package.json package-lock.json
	npm ci --no-audit --no-fund
	touch $@

$(HTMX): node_modules/htmx.org/dist/htmx.min.js
	mkdir -p $(dir $@)
	cp $< $@

/usr/bin/chromium:
	$(SUDO) apt-get update -qq
	$(SUDO) apt-get install -y -qq chromium

## make build: vendor leaderboard/, web/ and the resource definition into functions/vendor for the Lambda bundle
build: install
	$(BIN)/drem build

bench: install-test
	for b in bench/[!_]*.py; do $(BIN)/python $$b || exit 1; done

clean-state:
	rm -rf .drem
