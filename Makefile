# snakekit: `make lab` opens the lessons, `make test` runs the whole suite.
# Both set everything up first (tools/setup is fast when .venv is already current).

VENV    ?= .venv
PY      := $(VENV)/bin/python
LAB_PORT ?= 8888
LAB_IP  ?= 127.0.0.1
export PATH := $(abspath $(VENV))/bin:$(PATH)
export MUJOCO_GL ?= egl

.PHONY: setup lab test bench lock generate student check-generated clean references

setup:
	@tools/setup

# JupyterLab without rfc3987-syntax: jsonschema loads it, when installed, for an "iri" format
# check Jupyter never makes, and it compiles 25 Earley grammars on import (about 1.9 s of
# every start, more than half of the time to a ready JupyterLab; see bench/RESULTS.md).
LAB_MAIN := import sys; sys.modules["rfc3987_syntax"] = None; from jupyterlab.labapp import main; sys.exit(main())

# A student's JupyterLab: nbgrader's Validate button on, its teacher tools (formgrader, create
# assignment, the exchange's lists) off; tools/student-lab/labconfig/page_config.json hides their UI.
lab: setup
	@echo "snakekit: JupyterLab on the lessons in notebooks/ (the simulator is the default robot)"
	JUPYTER_CONFIG_PATH=$(CURDIR)/tools/student-lab $(PY) -c '$(LAB_MAIN)' --no-browser --allow-root \
	    --ip=$(LAB_IP) --port=$(LAB_PORT) \
	    --ServerApp.root_dir=notebooks --LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate \
	    --ServerApp.jpserver_extensions nbgrader.server_extensions.validate_assignment=True \
	    --ServerApp.jpserver_extensions nbgrader.server_extensions.formgrader=False \
	    --ServerApp.jpserver_extensions nbgrader.server_extensions.course_list=False \
	    --ServerApp.jpserver_extensions nbgrader.server_extensions.assignment_list=False

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
	$(PY) -m grader.references

clean:
	rm -rf $(VENV) .pytest_cache artifacts
