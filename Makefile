# snakekit: `make lab` opens the lessons, `make test` runs the whole suite.
# Both set everything up first (tools/setup is fast when .venv is already current).

VENV    ?= .venv
PY      := $(VENV)/bin/python
LAB_PORT ?= 8888
LAB_IP  ?= 127.0.0.1
export PATH := $(abspath $(VENV))/bin:$(PATH)
# MUJOCO_GL: the kit picks it for each system when it is imported (snakekit.host): EGL on Linux,
# MuJoCo's own default on macOS. A MUJOCO_GL set in the environment is kept.

.PHONY: setup lab test test-quick bench lock generate student check-generated clean references

setup:
	@tools/setup

# A student's JupyterLab on the lessons, on Linux or macOS: `snakekit start` checks the system first
# (and says what to install when something is missing), then starts JupyterLab with nbgrader's
# Validate button and without its teacher tools (snakekit/start.py has the options and why).
lab: setup
	$(VENV)/bin/snakekit start --ip=$(LAB_IP) --port=$(LAB_PORT)

# The suite in two parts at once (tools/run-tests): the tests marked `serial`, whose checks ride on
# the wall clock (the emulated bus and the arm's lab in real time), one at a time at a higher
# priority; beside them the rest in parallel (pytest-xdist, one worker per core: most of its time
# is spent waiting on subprocesses, the Docker engine and browsers; TEST_WORKERS=0: one process).
# Tests that share an expensive module fixture, or the Docker engine, stay on one worker
# (tests/conftest.py). Each run's durations: artifacts/test-durations.txt.
TEST_WORKERS ?= $(shell getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
export TEST_WORKERS

test: setup
	PY=$(PY) tools/run-tests "" $(PYTEST_ARGS)

# The contributor's loop: everything but the `system` tests (Docker, Binder, the hub, browsers,
# the lock's resolution, other platforms; tests/system/).
test-quick: setup
	PY=$(PY) tools/run-tests "not system" $(PYTEST_ARGS)

# Every benchmark under bench/, into bench/RESULTS.md and its plots (BENCH_ARGS: e.g. --only sim).
bench: setup
	$(PY) bench/run.py $(BENCH_ARGS)

lock:
	tools/lock

generate: setup
	$(VENV)/bin/snakekit generate
	$(PY) docker/ros/make-dockerfile

# The student versions in notebooks/ from the instructor versions in course/source/ (nbgrader).
student: setup
	$(PY) tools/generate_student

# Fails when a generated file (URDF, MJCF; the ROS image's Dockerfile) is out of date with its sources.
check-generated: setup
	$(VENV)/bin/snakekit generate --check
	$(PY) docker/ros/make-dockerfile --check

references: setup
	$(PY) -m grader.scoring.references

clean:
	rm -rf $(VENV) .pytest_cache artifacts
