# The two commands a newcomer needs:  make up   and   make test
# Everything else here is what those two call. Every Python package comes from the lock files in requirements/
# (exact versions + sha256 hashes), every npm package from package-lock.json; `make lock` refreshes them.
SHELL := /bin/bash
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
TOOLS := .tools
UV := $(TOOLS)/bin/uv
# torch (the CPU build, only for training: the tests and the booth) comes from PyTorch's CPU wheel index, pinned with
# its hash in requirements/torch-cpu.txt. A local folder holding that wheel is an optional speed-up: used when it
# exists and has the wheel (`make up WHEELS=~/wheels`), never required. Nothing else comes from it.
WHEELS ?= /opt/wheels
TORCH_WHEEL_INDEX := https://download.pytorch.org/whl/cpu/torch/
TORCH_SOURCE = $(if $(wildcard $(WHEELS)/torch-*+cpu-*.whl),--find-links $(WHEELS),--find-links $(TORCH_WHEEL_INDEX))
UV_INSTALL := $(UV) pip sync --quiet --python $(BIN)/python --require-hashes
UV_COMPILE = $(UV) pip compile --quiet --generate-hashes --python-version 3.11 \
	--python-platform x86_64-manylinux_2_28 $(TORCH_SOURCE) --constraint requirements/pins.txt \
	$(if $(UPGRADE),--upgrade,)
RUNTIME_LOCK := requirements/runtime.txt
# Everything the tests and lint need except torch, which requirements/torch-cpu.txt pins (its own source, above).
DEV_LOCK := requirements/dev.txt
TORCH_LOCK := requirements/torch-cpu.txt
# What `make deploy` needs: the CLI (drem build, drem aws) and the CDK app's Python side; no torch, no test tools.
DEPLOY_LOCK := requirements/deploy.txt
HTMX := web/drem_web/static/vendor/htmx.min.js
# Country flags as images (emoji flags show as letters on Windows and in the test Chromium).
FLAGS := web/drem_web/static/vendor/flags/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Fonts the result PDFs and labels embed (names in any script): Noto Sans + Noto Sans Arabic (OFL-1.1) and
# Droid Sans Fallback for CJK (Apache-2.0). `drem build` copies the few files it needs into the Lambda bundle.
FONT_DEBS := fonts-noto-core fonts-droid-fallback fonts-nanum
# Debian packages the tests and benches drive (apt pins them to the release's current, signed versions).
TEST_DEBS := chromium poppler-utils $(FONT_DEBS)
BENCH_DEBS := wrk nginx-light

.PHONY: up demo test lint install install-test install-deploy test-debs font-debs lock build bench clean-state deploy \
	destroy aws-check

## make up: install everything, then start the local event stack on http://127.0.0.1:8000
up: install
	$(BIN)/drem up $(ARGS)

## make demo: the same stack with a demo event, sim cars driving sample models and a race director (fills the boards live)
demo: install
	$(BIN)/drem up --demo $(ARGS)

# pytest-xdist workers for `make test`: one per core (CI has two). Each test file runs whole in one worker
# (--dist loadfile), handed out in collection order (--no-loadscope-reorder), which tests/conftest.py makes slowest
# tiers first; the infra tests take turns on functions/ (tests/infra/conftest.py). TEST_WORKERS=0: one process.
# One worker more than the cores was tried on 2 cores (2026-11-29): pytest 555-562 s instead of 606-628 s, but in one
# run of three tests/integration/test_chaos.py found a board still behind its race 10 s after the last restart; until
# that is understood the suite runs one worker per core.
TEST_WORKERS ?= auto
# Python compiles each module once, into .pycache/, and every later process reuses it: the workers and the many drem
# subprocesses the tests start. A shell's PYTHONDONTWRITEBYTECODE would otherwise make each of them compile everything
# it imports again (the app, moto and botocore: 3-5 s per process on a busy 2-core machine).
TEST_ENV := env -u PYTHONDONTWRITEBYTECODE PYTHONPYCACHEPREFIX=$(CURDIR)/.pycache

## make test: install the test dependencies (Python, npm htmx, Debian chromium), lint, then run every test
test: install-test
	$(MAKE) --no-print-directory lint
	$(TEST_ENV) $(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder $(PYTEST_ARGS)

## make lint: ruff (style and likely bugs), mypy (types; strict for leaderboard/ and chalicelib/domain/) and
## lint-imports (the layering of docs/architecture.md), as configured in pyproject.toml. mypy keeps its cache in
## .mypy_cache/ and lint-imports in .import_linter_cache/, so a second run takes seconds. A broken contract prints
## the import that breaks it.
lint: $(VENV)/.installed-test
	@status=0; $(BIN)/ruff check --quiet --output-format concise . || status=1; $(BIN)/mypy || status=1; \
	layers=$$(PYTHONPATH=functions $(BIN)/lint-imports 2>&1) || { echo "$$layers" | sed -n '/^Broken contracts/,$$p'; \
	status=1; }; exit $$status

install: $(VENV)/.installed-runtime $(HTMX) $(FLAGS) font-debs

install-test: $(VENV)/.installed-test $(HTMX) $(FLAGS) test-debs

$(UV):
	$(PYTHON) -m venv $(TOOLS)
	$(TOOLS)/bin/pip install --quiet --require-hashes -r requirements/tools.txt

$(VENV)/bin/python: | $(UV)
	$(UV) venv --quiet --python $(PYTHON) $(VENV)

# Sync makes the venv hold exactly the lock (nothing more), then drem itself goes in editable, without deps
# and without build isolation (its build backend comes from the lock too). The stamps say which lock the venv holds.
INSTALL_DREM := $(UV) pip install --quiet --python $(BIN)/python --no-deps --no-build-isolation -e .
$(VENV)/.installed-runtime: $(RUNTIME_LOCK) pyproject.toml | $(VENV)/bin/python
	$(UV_INSTALL) $(RUNTIME_LOCK)
	$(INSTALL_DREM)
	rm -f $(VENV)/.installed-test $(VENV)/.installed-deploy
	touch $@

$(VENV)/.installed-test: $(DEV_LOCK) $(TORCH_LOCK) pyproject.toml | $(VENV)/bin/python
	$(UV_INSTALL) $(DEV_LOCK)
	$(UV) pip install --quiet --python $(BIN)/python --require-hashes --no-deps $(TORCH_SOURCE) -r $(TORCH_LOCK)
	$(INSTALL_DREM)
	rm -f $(VENV)/.installed-runtime $(VENV)/.installed-deploy
	touch $@

$(VENV)/.installed-deploy: $(DEPLOY_LOCK) pyproject.toml | $(VENV)/bin/python
	$(UV_INSTALL) $(DEPLOY_LOCK)
	$(INSTALL_DREM)
	rm -f $(VENV)/.installed-runtime $(VENV)/.installed-test
	touch $@

# The test venv holds everything deploying needs too: keep it rather than shrink it to the deploy lock.
install-deploy: $(HTMX) $(FLAGS)
	@[ -f $(VENV)/.installed-test ] && [ $(VENV)/.installed-test -nt $(DEV_LOCK) ] || $(MAKE) --no-print-directory \
		$(VENV)/.installed-deploy

## make lock: re-resolve requirements/*.txt from pyproject.toml (keeps current pins; UPGRADE=1 takes the newest)
lock: | $(UV)
	$(UV_COMPILE) pyproject.toml requirements/build.in --all-extras --no-emit-package torch -o $(DEV_LOCK)
	@# torch and its dependencies (pinned as in the dev lock): installed --no-deps from its own source (TORCH_SOURCE).
	$(UV_COMPILE) requirements/torch-cpu.in --constraint $(DEV_LOCK) -o $(TORCH_LOCK)
	$(UV_COMPILE) pyproject.toml requirements/build.in --extra sim --extra car --extra convert --extra infra \
		--constraint $(DEV_LOCK) -o $(DEPLOY_LOCK)
	$(UV_COMPILE) pyproject.toml requirements/build.in --extra sim --extra car --extra convert --constraint $(DEV_LOCK) \
		-o $(RUNTIME_LOCK)
	@# Lambda's python3.11 runs on Amazon Linux 2 (glibc 2.26): manylinux2014 (glibc 2.17) wheels only.
	$(UV) pip compile --quiet --generate-hashes --python-version 3.11 --python-platform x86_64-manylinux_2_17 \
		$(if $(UPGRADE),--upgrade,) requirements/lambda.in --constraint $(RUNTIME_LOCK) -o requirements/lambda.txt
	@# The learning booth's container (booth/Dockerfile): drem with the simulator and training, same platform as
	@# the live server's below; torch is the CPU wheel (pins.txt), which the image build fetches from PyTorch's index.
	$(UV_COMPILE) pyproject.toml --extra sim --extra train --constraint $(DEV_LOCK) -o requirements/booth.txt
	@# The live-page server's container (live/Dockerfile): python:3.11-slim-bookworm on Fargate X86_64.
	$(UV) pip compile --quiet --generate-hashes --python-version 3.11 --python-platform x86_64-manylinux_2_28 \
		$(if $(UPGRADE),--upgrade,) requirements/live.in --constraint $(RUNTIME_LOCK) -o requirements/live.txt

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

font-debs:
	@$(call apt_install,$(FONT_DEBS))

define apt_install
missing=; for p in $(1); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
[ -z "$$missing" ] || { $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq $$missing; }
endef

## make build: vendor leaderboard/, web/ and the resource definition into functions/vendor for the Lambda bundle
build: install
	$(BIN)/drem build

## make bench: every bench/ script (each ends with a RESULT line); installs wrk and nginx for the spectator benches
## make deploy STAGE=dev [BOOTH=1]: deploy to the AWS account of your default credentials (docs/deploy.md); prints the URL
STAGE ?= dev
CDK := infra_cdk/node_modules/.bin/cdk
# Node.js 22 LTS (drem aws check refuses others; docs/deploy.md): no end-of-life warning to silence.
CDK_RUN := cd infra_cdk && node_modules/.bin/cdk
DEPLOYED := .drem-aws/$(STAGE).json
CDK_OUTPUTS := .drem-aws/$(STAGE).cdk-outputs.json
CDK_CONTEXT := -c stage=$(STAGE) $(if $(DOMAIN),-c domain_name=$(DOMAIN) -c certificate_arn=$(CERTIFICATE_ARN),) \
	$(if $(LIVE_MAX_TASKS),-c live_max_tasks=$(LIVE_MAX_TASKS),)
# SES_FROM=drem@example.org SES_IDENTITY_ARN=arn:aws:ses:...: Cognito emails through SES (docs/deploy.md, Email).
CDK_CONTEXT += $(if $(SES_FROM)$(SES_IDENTITY_ARN),-c ses_from='$(SES_FROM)' -c ses_identity_arn=$(SES_IDENTITY_ARN),)
# ALARM_EMAIL=ops@example.org: the stage's alarms (errors, throttling, live pages) email it (docs/deploy.md, Alarms).
CDK_CONTEXT += $(if $(ALARM_EMAIL),-c alarm_email='$(ALARM_EMAIL)',)
# BOOTH=1 adds the learning booth's Fargate task (docs/deploy.md, "The learning booth"): about 2.4 USD a day, always on.
CDK_CONTEXT += $(if $(BOOTH),-c booth=true,)
# UPLOAD_CONCURRENCY=0 on a new account (Lambda concurrency quota below 102): the upload checker's reserved concurrency.
CDK_CONTEXT += $(if $(UPLOAD_CONCURRENCY),-c upload_concurrency=$(UPLOAD_CONCURRENCY),)

$(CDK): infra_cdk/package.json infra_cdk/package-lock.json
	cd infra_cdk && npm ci --no-audit --no-fund
	touch $@

## make aws-check: what `make deploy` checks first (credentials, region, Node, Docker, fonts, flag images)
aws-check: install-deploy font-debs
	$(BIN)/drem aws check

deploy: install-deploy font-debs $(CDK)
	$(BIN)/drem aws check
	$(BIN)/drem build
	mkdir -p .drem-aws
	$(CDK_RUN) bootstrap $(CDK_CONTEXT)
	$(CDK_RUN) deploy drem-$(STAGE) $(CDK_CONTEXT) --require-approval never --outputs-file ../$(CDK_OUTPUTS)
	@# One pass: the functions read the public URL from the stack's SSM parameter (CloudFront's domain is known
	@# only once the distribution exists), so neither the first deploy nor a redeploy serves a fallback URL.
	$(BIN)/drem aws record --stage $(STAGE) --outputs $(CDK_OUTPUTS)
	$(BIN)/drem aws admin --stage $(STAGE)
	@echo "drem $(STAGE) is deployed: $$($(BIN)/python -c "import json;print(json.load(open('$(DEPLOYED)'))['public_url'])")"

## make destroy STAGE=dev: delete the stack; tables, buckets and the user pool are RETAINED (your event data stays)
destroy: $(CDK)
	@echo "Deleting stack drem-$(STAGE). Tables, buckets and the user pool are kept (RETAIN) with all event data;"
	@echo "delete them in the AWS console if you no longer need them. Export first: drem export --aws --stage $(STAGE)"
	@read -p "Type the stage name to confirm: " answer && [ "$$answer" = "$(STAGE)" ]
	$(CDK_RUN) destroy drem-$(STAGE) $(CDK_CONTEXT) --force
	rm -f $(DEPLOYED) $(CDK_OUTPUTS)

bench: install-test
	@$(call apt_install,$(BENCH_DEBS))
	for b in bench/[!_]*.py; do $(BIN)/python $$b || exit 1; done

clean-state:
	rm -rf .drem
