# The two commands of the README: `make run` and `make test` (plus `make test-fast` and
# `make bench`).
# Each first sets up .venv/ (idempotently) from requirements.txt and this package.

PYTHON ?= python3
VENV := $(CURDIR)/.venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# colcon and the tools it starts must be the venv's; ROS wheels need nothing sourced.
ENV := PATH="$(VENV)/bin:$$PATH"
# colcon's own folders are hidden so that the linters, which skip dot-folders, do not lint
# the copies of the sources it makes there.
COLCON := $(ENV) colcon --log-base .colcon/log
COLCON_PATHS := --paths $(CURDIR) --build-base .colcon/build --install-base .colcon/install
RUN_ARGS ?=
# 1: make run starts the simulated arm (wafer-sim) beside the node; 0: the node alone.
SIM ?= 1
# The tests run in JOBS pytest-xdist workers, a test file per worker at a time (each worker
# in a DDS domain of its own: test/conftest.py); JOBS=1 runs them in one process.
JOBS ?= 2
XDIST := $(if $(filter 1,$(JOBS)),-p no:xdist,-n $(JOBS) --dist loadfile)

.PHONY: setup kernels run test test-fast bench clean

setup: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg package.xml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@echo "Installing requirements.txt into .venv/ (about a minute, once):"
	$(PY) -m pip install --disable-pip-version-check --progress-bar on -r requirements.txt
	$(PY) -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation -e .
	@# setup.cfg puts console scripts where `ros2 run` looks; put them on the venv's PATH too.
	cd $(VENV)/bin && ln -sf ../lib/wafer_planner_ros/* .
	@touch $(STAMP)

# The planning kernels compiled for this machine once (numba's cache under
# ~/.cache/wafer_planner_ros/numba); later runs only load them, about a second.
kernels: $(STAMP)
	@$(ENV) $(PY) -m wafer_planner_ros.cli.kernels

# make run starts the simulated arm (wafer-sim: it executes the node's trajectories and
# publishes /joint_states) beside the node, with the same parameters; SIM=0 leaves it out.
# The sim ends with the node (Ctrl-C reaches the node; the sim is sent SIGTERM).
run: kernels
	@sim=; trap '[ -z "$$sim" ] || kill $$sim 2>/dev/null' EXIT; trap 'exit 130' INT TERM; \
	if [ "$(SIM)" != 0 ]; then \
		$(ENV) $(PY) -m wafer_planner_ros.node.sim --ros-args \
			--params-file config/wafer_planner.yaml $(RUN_ARGS) & sim=$$!; \
	fi; \
	$(ENV) $(PY) -m wafer_planner_ros.node.main --ros-args \
		--params-file config/wafer_planner.yaml $(RUN_ARGS)

test: $(STAMP)
	@# colcon copies the sources and never deletes a copy whose source has gone (a moved
	@# module): start from fresh copies, so that no stale module can be imported.
	rm -rf .colcon/build/wafer_planner_ros/build .colcon/install/wafer_planner_ros/lib
	$(COLCON) build $(COLCON_PATHS)
	@# The kernels of the copy the tests import, compiled before any test runs.
	@PYTHONPATH="$$(echo $(CURDIR)/.colcon/install/wafer_planner_ros/lib/python3*/site-packages)" \
		$(ENV) $(PY) -m wafer_planner_ros.cli.kernels
	$(COLCON) test $(COLCON_PATHS) --return-code-on-test-failure \
		--event-handlers console_direct+ --pytest-args -p no:cacheprovider $(XDIST)
	$(COLCON) test-result --test-result-base .colcon/build --verbose

# The inner loop while developing: the tests marked neither slow nor linter (the ament linters
# and the import contracts are left to `make test`), run on the sources in place (the editable
# install) with the kernels compiled for them; no colcon.
test-fast: kernels
	$(ENV) $(PY) -m pytest test -m "not slow and not linter" -p no:cacheprovider -q $(XDIST)

bench: kernels
	$(PY) -m pip install --disable-pip-version-check -q -r bench/requirements.txt
	$(ENV) $(PY) bench/bench_roadmap.py
	$(ENV) $(PY) bench/bench_plan.py
	$(ENV) $(PY) bench/bench_node.py
	$(ENV) $(PY) bench/bench_startup.py
	$(ENV) $(PY) bench/bench_live.py
	$(ENV) $(PY) bench/bench_cell.py
	$(ENV) $(PY) bench/bench_optimiser.py --seeds 1 2 3
	refs=$$(mktemp -d) && $(ENV) $(PY) bench/bench_free_moves.py --seeds 1 2 3 --references $$refs \
		&& $(ENV) $(PY) bench/bench_node_free_moves.py --seeds 1 2 3 --references $$refs
	$(ENV) $(PY) bench/bench_table.py
	$(ENV) $(PY) bench/bench_cycle.py --seeds 1 2 3
	$(ENV) $(PY) bench/bench_ports.py
	$(ENV) $(PY) bench/bench_port_table.py
	$(ENV) $(PY) bench/bench_study.py
	$(ENV) $(PY) bench/bench_stop.py
	$(ENV) $(PY) bench/bench_stop_node.py
	$(ENV) $(PY) bench/bench_divert.py

clean:
	rm -rf .colcon
