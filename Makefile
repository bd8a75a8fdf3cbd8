# Two commands set everything up and run: `make run` (simulator + wall follower on the default
# maze) and `make test` (the ruff linter, then pytest). Each creates .venv if missing, installs
# the pinned dependencies when requirements.lock or pyproject.toml changed, rebuilds
# amr_msgs (and tf2_msgs) when their sources changed, and compiles the numba kernels into
# their cache when their sources changed (so the first run is as fast as the next). `make
# test` also installs the cluster extra (Ray, requirements-cluster.lock: ~560 MB, ~30 s) so
# the Ray tests run, and the docs extra (MkDocs, requirements-docs.lock: ~110 MB) to build the
# manual; `make run` needs neither.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
DEPS_STAMP := $(VENV)/.stamp-deps
CLUSTER_STAMP := $(VENV)/.stamp-cluster
DOCS_STAMP := $(VENV)/.stamp-docs
MSGS_STAMP := $(VENV)/.stamp-amr_msgs
MSGS_SOURCES := $(wildcard amr_msgs/msg/*.msg amr_msgs/srv/*.srv) amr_msgs/CMakeLists.txt amr_msgs/package.xml \
	tools/cmake/ros_pypi_wheels.cmake tools/build_amr_msgs.py
# tf2_msgs (TFMessage for /tf) is not among the PyPI wheels: built into the venv unless an apt ROS
# install provides it. The amr_msgs stamp depends on it, so every target gets both.
TF2_STAMP := $(VENV)/.stamp-tf2_msgs
TF2_SOURCES := $(wildcard third_party/tf2_msgs/msg/*.msg) third_party/tf2_msgs/CMakeLists.txt \
	third_party/tf2_msgs/package.xml tools/cmake/ros_pypi_wheels.cmake tools/build_amr_msgs.py

# numba's cached kernels (tools/precompile.py): rebuilt when a file they are compiled from
# changed (the list comes from the tool, read with the system Python: no venv needed yet).
NUMBA_STAMP := $(VENV)/.stamp-numba
KERNEL_SOURCES := $(shell $(PYTHON) tools/precompile.py --sources)

ARGS ?=
PYTEST_ARGS ?=
# Local runs, tests and benchmarks stay on loopback (the scripts and tests/conftest.py also
# claim a free ROS_DOMAIN_ID). Robot runs (scripts/run_robot.py) are not started from here.
LOCAL_ROS := ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST

.PHONY: run test bench setup lock clean

run: $(MSGS_STAMP) $(NUMBA_STAMP)
	$(LOCAL_ROS) $(PY) scripts/run_sim.py $(ARGS)

# The manual is built after the linter and before pytest: a broken link or anchor fails the run
# within seconds (mkdocs --strict; not with --quiet, which hides the warnings --strict counts),
# and the site lands in site/ (not tracked). The variable silences Material for MkDocs' notice of its end of life (May 2027; docs/dependencies.md).
test: $(MSGS_STAMP) $(CLUSTER_STAMP) $(DOCS_STAMP) $(NUMBA_STAMP)
	$(PY) -m ruff check .
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict
	$(LOCAL_ROS) $(PY) -m pytest $(PYTEST_ARGS)

bench: $(MSGS_STAMP) $(NUMBA_STAMP)
	$(LOCAL_ROS) $(PY) scripts/bench.py $(ARGS)

setup: $(MSGS_STAMP) $(NUMBA_STAMP)

$(PY):
	$(PYTHON) -m venv $(VENV)

$(DEPS_STAMP): requirements.lock pyproject.toml | $(PY)
	$(PY) -m pip install --disable-pip-version-check -q -r requirements.lock
	$(PY) -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation -e .
	touch $@

$(CLUSTER_STAMP): $(DEPS_STAMP) requirements-cluster.lock
	$(PY) -m pip install --disable-pip-version-check -q -r requirements-cluster.lock \
		-c requirements.lock
	touch $@

$(DOCS_STAMP): $(CLUSTER_STAMP) requirements-docs.lock
	$(PY) -m pip install --disable-pip-version-check -q -r requirements-docs.lock \
		-c requirements.lock -c requirements-cluster.lock
	touch $@

$(TF2_STAMP): $(DEPS_STAMP) $(TF2_SOURCES)
	$(PY) tools/build_amr_msgs.py third_party/tf2_msgs --unless-provided
	touch $@

$(MSGS_STAMP): $(DEPS_STAMP) $(TF2_STAMP) $(MSGS_SOURCES)
	$(PY) tools/build_amr_msgs.py
	touch $@

# After the messages (the last step of the set-up), not because of them: headless episodes
# compile every kernel (~1 min from nothing) and the old cache files are removed first.
$(NUMBA_STAMP): $(DEPS_STAMP) $(KERNEL_SOURCES) | $(MSGS_STAMP)
	$(PY) tools/precompile.py
	touch $@

# Re-pin after editing requirements.in (needs network access to PyPI).
lock: | $(PY)
	rm -rf build/lock-venv && $(PYTHON) -m venv build/lock-venv
	build/lock-venv/bin/pip install -q -r requirements.in
	build/lock-venv/bin/python tools/pin_requirements.py > requirements.lock
	build/lock-venv/bin/pip install -q -r requirements-cluster.in -c requirements.lock
	build/lock-venv/bin/python tools/pin_requirements.py --exclude requirements.lock \
		--source "requirements-cluster.in on top of requirements.lock" > requirements-cluster.lock
	build/lock-venv/bin/pip install -q -r requirements-docs.in -c requirements.lock \
		-c requirements-cluster.lock
	build/lock-venv/bin/python tools/pin_requirements.py --exclude requirements.lock \
		--exclude requirements-cluster.lock \
		--source "requirements-docs.in on top of both locks" > requirements-docs.lock
	rm -rf build/lock-venv

clean:
	rm -rf $(VENV) build site
