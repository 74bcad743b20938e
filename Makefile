# Two commands matter: `make demo` and `make test`. Both create .venv when it is
# missing and install every pinned dependency and the five packages into it.
SHELL := /bin/bash
# The venv's interpreter: PYTHON when given; else Debian's own Python 3.11 where it makes a
# venv (Debian ships venv's pip apart, in python3.11-venv), else python3 on the PATH. Debian
# builds it with profile-guided and link-time optimisation and links the interpreter
# statically; a plain source build (pyenv's default: shared library, neither optimisation) runs
# the suite's interpreted code about 15 % slower (docs/benchmarks.md).
SYSTEM_PYTHON := /usr/bin/python3.11
ifdef PYTHON
MAKE_VENV = $(PYTHON) -m venv $(VENV)
else
MAKE_VENV = { $(SYSTEM_PYTHON) -m venv $(VENV) 2>/dev/null || { rm -rf $(VENV) && python3 -m venv $(VENV); }; }
endif
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
PACKAGES := src/buoy_common src/sensor_sim src/buoy_nav src/wind_comp src/buoy_processing
PACKAGE_FILES := $(foreach p,$(PACKAGES),$(p)/setup.py $(p)/setup.cfg $(p)/package.xml)
# DDS traffic stays on loopback. Every live run takes a domain of its own unless the caller
# chose one (ROS_DOMAIN_ID): the tests, demo, bags and benchmarks each claim one from their own
# range in tools/ros_domains.py.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export AMENT_PREFIX_PATH := $(CURDIR)/$(VENV)
export PYTHONUNBUFFERED := 1

.PHONY: all venv compiled bytecode demo test test-long bench mutants lint format bags colcon clean help

all: help

help:
	@echo "make demo   - set up .venv and run the live demo (simulated buoy, fusion, wind correction)"
	@echo "make test   - set up .venv, lint, and run the test suite (all but the long runs)"
	@echo "make test-long - the long runs: live fault matrix, double signals, soak, archive, DVL replay, real record replay"
	@echo "make bench  - accuracy and speed tables beside the paper's (prints them, writes out/bench/results.json)"
	@echo "make mutants - flip signs and conventions of the core on a copy, report which tests catch each"
	@echo "make bags   - re-record the committed bags in bags/ from the live simulation nodes"
	@echo "make colcon - colcon build of ros2_ws inside the venv"
	@echo "make compiled - compile the numba code into its cache again (after a change of the sources)"
	@echo "make format - ruff format + autofix"

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt $(PACKAGE_FILES)
	@test -x $(BIN)/python || $(MAKE_VENV)
	$(BIN)/python -m pip install --quiet --upgrade "pip==25.3"
	$(BIN)/python -m pip install --quiet -r requirements-dev.txt
	$(BIN)/python -m pip install --quiet --no-build-isolation --no-deps $(foreach p,$(PACKAGES),-e $(p))
	# The tools are the package `tools` of the repository's root: `python -m tools.bench` from
	# the root; with the root on the venv's path, `.venv/bin/python tools/bench.py` too.
	$(BIN)/python -c 'import pathlib, site; pathlib.Path(site.getsitepackages()[0], "buoy_wind_tools.pth").write_text("$(CURDIR)\n")'
	@touch $(STAMP)

# numba's cache of a compiled function is judged by its own file's time alone, and the kernels
# compose functions of other files (kalman_kernel.py, earth.py, rotations.py, the layout of
# strapdown_kernel.py): after a change to any source of the packages every cached function is
# removed and the code compiled again, once, so that the processes of a run started together
# do not each compile it and none runs a stale composition.
COMPILED_STAMP := $(VENV)/.compiled-code
PACKAGE_SOURCES := $(shell find $(PACKAGES) -name '*.py' -not -path '*/test/*')

compiled: $(COMPILED_STAMP)

$(COMPILED_STAMP): $(STAMP) $(PACKAGE_SOURCES)
	find src tools -name '*.nbi' -delete -o -name '*.nbc' -delete
	$(BIN)/python -m tools.compile_ahead
	@touch $(COMPILED_STAMP)

# Where the environment sets PYTHONDONTWRITEBYTECODE, no process writes the bytecode of the
# suite's own modules, and each of the hundreds a test run starts compiles them again (about
# 0.4 s of CPU). Written here, every process reads it; only changed sources are compiled again.
bytecode: compiled
	$(BIN)/python -m compileall -q src tools tests

lint: venv
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: venv
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# Long runs (marker `long`: the live fault matrix, double signals to every executable, the
# soak, the archive on a Dask cluster, the DVL's and the real record's live replays) belong
# to `make bench`.
test: venv lint bytecode
	$(BIN)/python -m pytest -n auto --dist loadgroup -m "not long"

test-long: venv bytecode
	$(BIN)/python -m pytest -n auto --dist loadgroup -m long

demo: venv bytecode
	$(BIN)/python -m tools.demo

bench: venv bytecode
	$(BIN)/python -m tools.bench
	$(MAKE) test-long

mutants: compiled
	$(BIN)/python -m tools.mutation_check

bags: compiled
	$(BIN)/python -m tools.record_bags

colcon: venv
	# The venv is no colcon install space: without this, colcon warns that it lacks local_setup.
	cd ros2_ws && env -u AMENT_PREFIX_PATH ../$(BIN)/colcon build --symlink-install

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log out .pytest_cache .ruff_cache
