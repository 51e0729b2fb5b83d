# The README's two commands: `make demo` and `make test`. Both create .venv on first use.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test lint bench venv clean

venv: $(STAMP)

$(STAMP): requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements.txt
	touch $(STAMP)

# splat-transform (npm, package.json): the tests' oracle for the splat formats; without npm they skip and say so.
NODE_STAMP := node_modules/.installed
$(NODE_STAMP): package.json package-lock.json
	npm ci --no-audit --no-fund && touch $(NODE_STAMP) || echo "npm ci failed: the splat-format oracle tests will skip"

demo: $(STAMP)
	$(PY) -m gt2gs_blender demo

# Tests use the real ImageNet weights from ../shared (one test covers the no-weights fallback itself).
test: $(STAMP) $(NODE_STAMP) lint
	GT2GS_WEIGHTS_DIR=$${GT2GS_WEIGHTS_DIR:-$(abspath ../shared/weights)} $(PY) -m pytest -q

# Style and architecture: ruff (lint + format) and the import contracts in pyproject.toml.
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports

bench: $(STAMP)
	$(PY) bench/raster.py --quick

clean:
	rm -rf $(VENV) bench/out .pytest_cache
