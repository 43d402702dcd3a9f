# snakekit: `make lab` opens the lessons, `make test` runs the whole suite.
# Both set everything up first (tools/setup is fast when .venv is already current).

VENV    ?= .venv
PY      := $(VENV)/bin/python
LAB_PORT ?= 8888
LAB_IP  ?= 127.0.0.1
export PATH := $(abspath $(VENV))/bin:$(PATH)
# MUJOCO_GL: the kit picks it for each system when it is imported (snakekit.host): EGL on Linux,
# MuJoCo's own default on macOS. A MUJOCO_GL set in the environment is kept.

.PHONY: setup lab test bench lock generate student check-generated clean references

setup:
	@tools/setup

# A student's JupyterLab on the lessons, on Linux or macOS: `snakekit start` checks the system first
# (and says what to install when something is missing), then starts JupyterLab with nbgrader's
# Validate button and without its teacher tools (snakekit/start.py has the options and why).
lab: setup
	$(VENV)/bin/snakekit start --ip=$(LAB_IP) --port=$(LAB_PORT)

test: setup
	$(PY) -m pytest -q $(PYTEST_ARGS)

# Every benchmark under bench/, into bench/RESULTS.md and its plots (BENCH_ARGS: e.g. --only sim).
bench: setup
	$(PY) bench/run.py $(BENCH_ARGS)

lock:
	tools/lock

generate: setup
	$(VENV)/bin/snakekit generate

# The student versions in notebooks/ from the instructor versions in course/source/ (nbgrader).
student: setup
	$(PY) tools/generate_student

# Fails when a generated file (URDF, MJCF) is out of date with the spec it comes from.
check-generated: setup
	$(VENV)/bin/snakekit generate --check

references: setup
	$(PY) -m grader.scoring.references

clean:
	rm -rf $(VENV) .pytest_cache artifacts
