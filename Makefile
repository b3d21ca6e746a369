# Two entry points for a fresh machine: `make fly` (the main job) and `make test`.
# Each creates .venv and installs the project from pyproject.toml on first use.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed-stamp

.PHONY: fly test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

fly: $(STAMP)
	$(VENV)/bin/preland fly missions/thesis_square_land.yaml

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/sim_speed.py
	$(VENV)/bin/python benchmarks/normal_landing_table.py

clean:
	rm -rf $(VENV) build *.egg-info
