# scenebot: the two set-up commands of the README, and helpers.
#   make demo   install everything, run the default campaign (simulated office)
#   make test   install everything, lint, run the tests (fast and slow; what CI runs)
#   make report after a campaign: report.html, its pictures, tables, tour video and rule graph

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
CORES  ?= 2
# Debian packages the project needs: libusb for open3d's import; the tests also drive the
# tour's web viewer in headless Chromium (Selenium with Debian's chromedriver, no downloads)
# and run the workflow on a one-node SLURM cluster (scripts/slurm-local).
APT_PACKAGES := libusb-1.0-0
TEST_APT_PACKAGES := chromium chromium-driver munge slurmctld slurmd slurm-client
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
export TI_SKIP_VERSION_CHECK := ON

.PHONY: demo report test test-fast lint format system system-test install clean-results

system-test: APT_PACKAGES += $(TEST_APT_PACKAGES)
system-test: system

system:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	fi

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev]'
	touch $@

install: system $(VENV)/.installed

demo: install
	$(BIN)/snakemake --cores $(CORES)

report: install
	$(BIN)/snakemake --report report.html

lint: install
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/snakefmt --check Snakefile rules/
	$(BIN)/snakemake --lint

test: system-test lint
	$(BIN)/python -m pytest -m "not hardware and not gpu" -n auto --maxprocesses 4 --dist loadfile --no-loadscope-reorder --durations=25

test-fast: install
	$(BIN)/python -m pytest

format: install
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .
	$(BIN)/snakefmt Snakefile rules/

clean-results:
	@echo "results/ holds your photos: remove it by hand if you really mean to."
