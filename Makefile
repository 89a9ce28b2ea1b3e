# Two commands do all the set-up on a fresh machine (see README.md):
#   make demo   installs everything, then runs the main job on the embedded procedural objects
#   make test   installs everything, then runs the default test suite (what CI runs)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
# What to install: every extra and the test tools by default. A smaller venv for generating and
# simulating only (no torch, no Ray, no CVXPY): make setup EXTRAS=sim,board,import
EXTRAS ?= all,dev
comma  := ,
STAMP  := $(VENV)/.installed-$(subst $(comma),-,$(EXTRAS))
DEMO   := runs/demo

.PHONY: setup demo test test-all test-warp lint format clean docs

setup: $(STAMP)

$(STAMP): pyproject.toml
	bash scripts/install_system_deps.sh
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --progress-bar on --upgrade pip
	# torch first, pinned and the CPU build (only for the learning extras): an unpinned torch
	# pulls gigabytes of CUDA wheels
	bash scripts/install_torch.sh $(BIN)/python '$(EXTRAS)'
	$(BIN)/python -m pip install --progress-bar on -e '.[$(EXTRAS)]'
	touch $(STAMP)

demo: $(STAMP)
	# the main job end to end (objects, grasps, a labelled benchmark, two baselines scored,
	# a local leaderboard and its page); prints each step's command and where everything is
	$(BIN)/dg16m demo --out $(DEMO) --workers 2

test: $(STAMP)
	# the page tests' browser; the real furniture library (the importer's tests)
	bash scripts/install_system_deps.sh chromium chromium-driver sweethome3d-furniture
	$(BIN)/python -m pytest -q

test-all: $(STAMP)
	bash scripts/install_system_deps.sh chromium chromium-driver sweethome3d-furniture
	$(BIN)/python -m pytest -q -m ""

# Optional: MuJoCo Warp (`--simulator warp`). Installs the extra into .venv, then runs its tests
# on Warp's CPU device (the first run compiles Warp's kernels: 1-2 minutes, then cached).
test-warp: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[warp]'
	$(BIN)/python -m pytest -q -m warp tests/test_warp.py

# The documentation site (docs/, Sphinx + MyST + furo): warnings are errors; the pages of the
# environments, the API reference and the command line are generated from the code. Open
# docs/_build/html/index.html. Pictures of trials: MUJOCO_GL=egl $(BIN)/python scripts/docs_pictures.py
docs: $(STAMP)
	$(BIN)/sphinx-build -W --keep-going -b html -d docs/_build/doctrees docs docs/_build/html

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

clean:
	rm -rf $(VENV) runs .pytest_cache .ruff_cache *.egg-info
