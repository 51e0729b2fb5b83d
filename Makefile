# The README's two commands: `make demo` and `make test`. Both create .venv on first use.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-blender52 test-numpy2 test-gui lint build bench venv clean

venv: $(STAMP)

$(STAMP): requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.txt
	touch $(STAMP)

# Blender 5.2 LTS runs Python 3.13: its bpy (5.2.3) and numpy 2 in a venv of their own (pyenv's 3.13 when
# python3.13 is not on PATH; PYTHON313=... to choose).
PYTHON313 ?= $(shell for p in python3.13 $${PYENV_ROOT:-$$HOME/.pyenv}/versions/3.13*/bin/python3.13; do \
	$$p -c '' 2>/dev/null && { echo $$p; break; }; done)
VENV313 := .venv313
STAMP313 := $(VENV313)/.installed

$(STAMP313): requirements-py313.txt
	@test -n "$(PYTHON313)" || { echo "no Python 3.13 found for the Blender 5.2 tests: set PYTHON313"; exit 1; }
	$(PYTHON313) -m venv $(VENV313)
	$(VENV313)/bin/python -m pip install --quiet --upgrade pip
	$(VENV313)/bin/python -m pip install --quiet -r requirements-py313.txt
	touch $(STAMP313)

# The engine on numpy 2 (what Blender 5.1/5.2's dependencies install), with .venv's Python and torch.
VENVNP2 := .venv-numpy2
STAMPNP2 := $(VENVNP2)/.installed

$(STAMPNP2): requirements-numpy2.txt
	$(PYTHON) -m venv $(VENVNP2)
	$(VENVNP2)/bin/python -m pip install --quiet --upgrade pip
	$(VENVNP2)/bin/python -m pip install --quiet -r requirements-numpy2.txt
	touch $(STAMPNP2)

# splat-transform (npm, package.json): the tests' oracle for the splat formats; without npm they skip and say so.
NODE_STAMP := node_modules/.installed
$(NODE_STAMP): package.json package-lock.json
	npm ci --no-audit --no-fund && touch $(NODE_STAMP) || echo "npm ci failed: the splat-format oracle tests will skip"

demo: $(STAMP)
	$(PY) -m gt2gs_blender demo

# Tests use the real ImageNet weights from ../shared (one test covers the no-weights fallback itself).
test: $(STAMP) $(NODE_STAMP) lint
	GT2GS_WEIGHTS_DIR=$${GT2GS_WEIGHTS_DIR:-$(abspath ../shared/weights)} $(PY) -m pytest -q
	$(MAKE) test-blender52
	$(MAKE) test-numpy2

# The Blender edge (tests/blender) and the numpy-only readers on bpy 5.2.3 / Python 3.13 / numpy 2. The worker
# and the machine check run on .venv's Python (torch), as an artist's would on the installed dependencies.
test-blender52: $(STAMP) $(STAMP313) $(NODE_STAMP)
	GT2GS_WORKER_PYTHON=$(abspath $(PY)) GT2GS_WEIGHTS_DIR=$${GT2GS_WEIGHTS_DIR:-$(abspath ../shared/weights)} \
	  $(VENV313)/bin/python -m pytest -q tests/blender tests/test_fuzz_readers.py

# The engine's numpy parts and a transfer on numpy 2: every splat format, the scene, the worker, the transfer and
# the cameras (about 4 minutes).
test-numpy2: $(STAMPNP2) $(NODE_STAMP)
	GT2GS_WEIGHTS_DIR=$${GT2GS_WEIGHTS_DIR:-$(abspath ../shared/weights)} $(VENVNP2)/bin/python -m pytest -q \
	  tests/test_ply.py tests/test_splat_files.py tests/test_sog.py tests/test_spz.py tests/test_compressed_ply.py \
	  tests/test_scene.py tests/test_worker.py tests/test_transfer.py tests/test_cameras.py

# A real Blender window: Debian sid's blender (5.2.2, Python 3.14) in a debootstrap chroot under Xvfb runs
# tests/gui/smoke.py on the built zip and checks what it found. Not part of make test: it needs root and a Debian
# mirror, and takes several minutes (the chroot is kept in /var/tmp/gt2gs-sid). GUI_DOCS=1: docs/gui_*.jpg too.
test-gui: $(STAMP) $(STAMP313)
	bash tests/gui/run.sh

# Style and architecture: ruff (lint + format) and the import contracts in pyproject.toml.
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports

# The extension zip, dist/gt2gs_blender-<version>.zip, by Blender's own extension tool from the bpy wheel
# (Blender's tool refuses a missing output folder, so it is made first).
build: $(STAMP)
	mkdir -p dist
	$(PY) "$$($(PY) -c 'import bpy; print(bpy.utils.system_resource("SCRIPTS"))' | tail -n 1)/addons_core/bl_pkg/cli/blender_ext.py" \
	  build --source-dir gt2gs_blender --output-dir dist

bench: $(STAMP)
	$(PY) bench/raster.py --quick

clean:
	rm -rf $(VENV) $(VENV313) $(VENVNP2) dist bench/out .pytest_cache
