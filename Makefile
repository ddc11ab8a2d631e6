# Every target creates .venv when it is missing. Python 3.11+ required.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install test demo bench clean

install: $(STAMP)

$(STAMP): pyproject.toml setup.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	@touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q tests

# three legs in one graph (cargo_transport.DEMO_LEGS): no bag (PD), the FEM bag (fast solver,
# PD), the FEM bag flown by the sampling MPC (robot queen); runs/<t>/: summary.json, one plot
# and one MP4 per leg
demo: $(STAMP)
	$(VENV)/bin/astrobee launch cargo_transport --demo

bench: $(STAMP)
	$(PY) bench/run_all.py

clean:
	rm -rf $(VENV) build *.egg-info runs
