# apc — two commands do everything on a fresh Debian/Ubuntu machine with Python 3.11+:
#   make run    set up .venv and run the paper experiment
#   make test   set up .venv and run the whole test suite
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(VENV)/bin/pip
PKGS   := src/apc_msgs_py src/apc_core src/apc_recording src/apc_feedforward src/apc_feedback \
          src/apc_plant_sim src/apc_lab
STAMP  := $(VENV)/.apc-installed

.PHONY: setup test test-fast lint run bench colcon clean

setup: $(STAMP)

# apc's packages are uninstalled before they are installed: a console script that moved between
# packages would otherwise be deleted by the old package's uninstall after the new one wrote it.
$(STAMP): requirements.txt constraints.txt $(foreach p,$(PKGS),$(p)/setup.py)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade "pip==26.3"
	$(PIP) install -q "setuptools==79.0.1"
	$(PIP) install -q -r requirements.txt -c constraints.txt
	$(PIP) uninstall -q -y $(notdir $(PKGS)) 2>/dev/null || true
	$(PIP) install -q --no-deps --no-build-isolation $(foreach p,$(PKGS),-e $(p))
	touch $(STAMP)

test: setup
	$(VENV)/bin/pytest

test-fast: setup
	$(VENV)/bin/pytest -m "not slow"

lint: setup
	$(VENV)/bin/ruff check src test bench tools
	$(VENV)/bin/ruff format --check src test bench tools

run: setup
	$(PY) -m apc_lab.reproduce --out runs

# bench/results.json + results.md, < 10 min on 2 cores (BENCH_ARGS=--quick: ~4 min); no timing
# is asserted anywhere in make test.
bench: setup
	$(PY) bench/run_all.py $(BENCH_ARGS)

colcon: setup
	rm -rf build install log
	$(VENV)/bin/colcon build --base-paths src

clean:
	rm -rf build install log .pytest_cache
