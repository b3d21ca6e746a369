# Two entry points for a fresh machine: `make campaign` (the main job) and `make test`.
# Each creates .venv and installs the project from pyproject.toml on first use.
# The interpreter .venv is made from: the system's own /usr/bin/python3 when it is 3.11 or newer and can make a
# venv, else python3 on PATH; `make PYTHON=...` chooses another. Debian builds its python3 with profile-guided and
# link-time optimisation into one static binary; an interpreter built from source without --enable-optimizations
# (as the pyenv builds on the CI machine are) runs preland's simulations slower (see docs/contributing.md).
# An existing .venv is kept whatever its interpreter: `make clean` first to change it.
SYSTEM_PYTHON := /usr/bin/python3
PYTHON ?= $(shell $(SYSTEM_PYTHON) -c 'import sys, ensurepip; sys.exit(sys.version_info < (3, 11))' \
	>/dev/null 2>&1 && echo $(SYSTEM_PYTHON) || echo python3)
VENV := .venv
STAMP := $(VENV)/.installed-stamp

.PHONY: campaign fly test docs bench clean

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

# Each test module on one worker (--dist loadfile): a module's Ray tests share its one local Ray instance. The
# modules go out in collection order (--no-loadscope-reorder), which puts the longest first (tests/conftest.py).
# Six workers on a 2-core machine: many tests wait in wall time (Ray starting and stopping, the SITL stand-in
# flying at its speed-up, a lost link's bound), and the extra workers keep both cores busy meanwhile.
# The suite starts hundreds of Python processes (campaign workers, CLI runs, tutorials): with bytecode written
# (PYTHONDONTWRITEBYTECODE emptied, where the environment sets it), each module is compiled once, not in each.
# Collecting once first writes the test modules' compiled (assertion-rewritten) code and preland's bytecode, which
# the six workers then read: on a fresh checkout each worker would otherwise compile them all at once.
test: $(STAMP)
	PYTHONDONTWRITEBYTECODE= $(VENV)/bin/python -m pytest -q --collect-only -p no:cacheprovider >/dev/null || true
	PYTHONDONTWRITEBYTECODE= $(VENV)/bin/python -m pytest -q -n 6 --dist loadfile --no-loadscope-reorder

# Builds the docs site into site/ (strict: a broken link or a missing page fails).
# The two variables silence the notices MkDocs plugins print about MkDocs 2 (see docs/contributing.md).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 DISABLE_MKDOCS_2_WARNING=true $(VENV)/bin/mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(VENV)/bin/python benchmarks/record.py sim_speed.py
	$(VENV)/bin/python benchmarks/record.py vision_speed.py
	$(VENV)/bin/python benchmarks/record.py loop_speed.py
	$(VENV)/bin/python benchmarks/record.py speed_budget.py
	$(VENV)/bin/python benchmarks/record.py detector_variants.py
	$(VENV)/bin/python benchmarks/record.py face_speed.py
	$(VENV)/bin/python benchmarks/record.py bridge_step.py
	$(VENV)/bin/python benchmarks/record.py campaign_wall_time.py
	$(VENV)/bin/python benchmarks/record.py executor_overhead.py
	$(VENV)/bin/python benchmarks/record.py store_growth.py
	$(VENV)/bin/python benchmarks/record.py normal_landing_table.py
	$(VENV)/bin/python benchmarks/record.py land_modes_table.py
	$(VENV)/bin/python benchmarks/record.py fault_scenarios_table.py
	$(VENV)/bin/python benchmarks/record.py drop_rate_sensitivity.py
	$(VENV)/bin/python benchmarks/record.py fault_kinds.py
	$(VENV)/bin/python benchmarks/record.py error_budget.py
	$(VENV)/bin/python benchmarks/record.py paper_table.py
	@if [ -n "$$PRELAND_SITL_BINARY" ]; then $(VENV)/bin/python benchmarks/record.py sitl_vs_embedded.py && \
	$(VENV)/bin/python benchmarks/record.py agreement_rule_noise.py && \
	$(VENV)/bin/python benchmarks/record.py json_bridge_hover.py && \
	$(VENV)/bin/python benchmarks/record.py sitl_air.py && \
	$(VENV)/bin/python benchmarks/record.py drop_cost_witnesses.py --sitl "PRELAND_SITL_BINARY=$$PRELAND_SITL_BINARY"; \
	else echo "benchmarks/sitl_vs_embedded.py, agreement_rule_noise.py (it reads its record), json_bridge_hover.py, sitl_air.py, drop_cost_witnesses.py skipped: set PRELAND_SITL_BINARY to an arducopter SITL binary"; fi

clean:
	rm -rf $(VENV) build site *.egg-info
