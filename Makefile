# Two commands do all the set-up on a fresh machine:
#   make run    create the environment and run the main job (the default stack, recorded)
#   make test   create the environment and run the tests
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed

.PHONY: run test lint bench screenshot clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -e '.[dev]' --config-settings editable_mode=compat
	$(VENV)/bin/pip install --quiet --no-deps trackeval==1.3.0
	touch $(STAMP)

run: $(STAMP)
	$(VENV)/bin/harvest run

test: $(STAMP)
	$(VENV)/bin/python -m pytest

lint: $(STAMP)
	$(VENV)/bin/ruff check schemas services tests deploy
	$(VENV)/bin/ruff format --check schemas services tests deploy
	$(VENV)/bin/mypy
	$(VENV)/bin/python -m schemas.export

bench: $(STAMP)
	$(VENV)/bin/harvest bench bus
	$(VENV)/bin/harvest bench viz
	$(VENV)/bin/harvest bench sim

# A headless screenshot of a recording (CPU-only machines: apt-get install mesa-vulkan-drivers)
VIEW ?= tests/fixtures/viz_small.mcap
SHOT ?= docs/viz_fixture.png
screenshot: $(STAMP)
	$(VENV)/bin/harvest view $(VIEW) --screenshot $(SHOT)

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
