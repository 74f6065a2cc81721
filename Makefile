# One-command set-up and the two entry points (see README.md).
#   make test     install everything, then run the test suite (which includes `make lint`)
#   make lint     snakemake --lint: must find nothing (see README)
#   make faults   the long fault-injection test (kills in every stage, resumed; ~10 min)
#   make figures  install everything, then run the default workflow (snakemake --cores 2)
#   make quick    install everything, then the smoke run of every stage (config/quick.yaml, ~2-4 min)
#   make test-slurm  only the tests on a one-node SLURM cluster (root; installs SLURM from Debian)
#   make docs     the manual (Sphinx) into docs/_build/html; the test suite builds it too
# Set-up is idempotent: stamps in .venv/ skip work already done.

SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
APT_PACKAGES := liggghts openmpi-bin libglu1-mesa libgl1 libxrender1 libxcursor1 libxfixes3 \
	libxext6 libxft2 libfontconfig1 libxinerama1 libx11-6 libgomp1 libegl1 libegl-mesa0 libgl1-mesa-dri
CORES ?= 2

.PHONY: setup system venv test lint faults test-slurm figures quick report docs clean-results

setup: system venv

# Debian packages: LIGGGHTS (+OpenMPI) and the GL/EGL libraries gmsh and VTK load.
system:
	@missing=$$(for p in $(APT_PACKAGES); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	if [ -n "$$missing" ]; then \
		echo "apt-get install:" $$missing; \
		SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
		$$SUDO apt-get update -q && \
		DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q --no-install-recommends $$missing; \
	fi

$(VENV)/.stamp-venv: pyproject.toml
	test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install -q -e '.[test]'
	touch $@

venv: $(VENV)/.stamp-venv

# One pytest worker per core, each test file on one worker (its module fixtures built once): most
# tests wait on LIGGGHTS, Snakemake or a SLURM job, so two workers halve the suite's time. The
# longest files are handed out first (tests/conftest.py), so that no long one runs on alone at the end.
test: setup
	$(VENV)/bin/python -m pytest -q -n $(CORES) --dist loadfile

# `snakemake --lint` must find nothing; tests/workflow/test_workflow.py parses its findings, so `make test`
# runs it too.
lint: setup
	$(VENV)/bin/python -m pytest -q tests/workflow/test_workflow.py -k lint

# The long fault-injection run: the tiny workflow killed three times in every stage, at random
# points, in random ways, and every kind of result damaged in every way (tests/workflow/test_faults.py;
# `make test` kills once per stage and damages each kind of result one way).
faults: setup
	DPHT_FAULT_KILLS=3 DPHT_DAMAGE_ROUNDS=4 $(VENV)/bin/python -m pytest -q -s tests/workflow/test_faults.py

test-slurm: setup
	$(VENV)/bin/python -m pytest -q -m slurm

figures: setup
	source $(VENV)/bin/activate && snakemake --cores $(CORES)

quick: setup
	source $(VENV)/bin/activate && snakemake --cores $(CORES) --configfile config/quick.yaml

report: figures
	source $(VENV)/bin/activate && snakemake --cores $(CORES) --report results/report.html

# The manual: Markdown pages under docs/, with the config keys and the command-line help written from
# the schema and the parser at build time (docs/_ext/generated_pages.py), and the example gallery,
# whose scripts (docs/examples/) sphinx-gallery runs at build time. Offline: no intersphinx.
docs: setup
	$(VENV)/bin/python -m sphinx -b html -q docs docs/_build/html
	@echo "manual: docs/_build/html/index.html"

clean-results:
	rm -rf results .snakemake
