# Two entry points for a fresh machine: `make campaign` (the main job) and `make test`.
# Each creates .venv and installs the project from pyproject.toml on first use.
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed-stamp

.PHONY: campaign fly test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --upgrade pip
	$(VENV)/bin/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# Runs the thesis' Table 3 campaign on the embedded simulator (finishing it if an earlier run
# was interrupted) and writes its report to out/report.
campaign: $(STAMP)
	mkdir -p out
	$(VENV)/bin/preland campaign run campaigns/thesis_table3.yaml --db out/results.db --resume --report out/report

fly: $(STAMP)
	$(VENV)/bin/preland fly missions/thesis_square_land.yaml

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q -n 4 --dist loadgroup

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/sim_speed.py
	$(VENV)/bin/python benchmarks/vision_speed.py
	$(VENV)/bin/python benchmarks/loop_speed.py
	$(VENV)/bin/python benchmarks/speed_budget.py
	$(VENV)/bin/python benchmarks/detector_variants.py
	$(VENV)/bin/python benchmarks/face_speed.py
	$(VENV)/bin/python benchmarks/campaign_wall_time.py
	$(VENV)/bin/python benchmarks/executor_overhead.py
	$(VENV)/bin/python benchmarks/store_growth.py
	$(VENV)/bin/python benchmarks/normal_landing_table.py
	$(VENV)/bin/python benchmarks/land_modes_table.py
	$(VENV)/bin/python benchmarks/fault_scenarios_table.py
	$(VENV)/bin/python benchmarks/drop_rate_sensitivity.py
	$(VENV)/bin/python benchmarks/paper_table.py
	@if [ -n "$$PRELAND_SITL_BINARY" ]; then $(VENV)/bin/python benchmarks/sitl_vs_embedded.py; \
	else echo "benchmarks/sitl_vs_embedded.py skipped: set PRELAND_SITL_BINARY to an arducopter SITL binary"; fi

clean:
	rm -rf $(VENV) build *.egg-info
