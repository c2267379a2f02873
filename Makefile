# Set-up and main jobs. `make run` and `make test` first install what is missing:
#  * with apt-get (through sudo only when not root): libsuitesparse-dev and libopenblas0-pthread (the
#    threaded OpenBLAS: CHOLMOD's supernodal factorizations use every core); for a
#    Debian-packaged interpreter its venv and header packages (python3.X-venv, python3.X-dev); gcc when
#    scikit-sparse has to be compiled and there is no C compiler;
#  * the virtual environment .venv, made from $(PYTHON), with this checkout installed in it (editable,
#    with the dev extras). Nothing is ever installed into $(PYTHON) itself: a Debian system interpreter
#    refuses (PEP 668, "externally managed") and a pyenv or conda base interpreter serves other projects.
#    When $(PYTHON) already has numpy, .venv sees its packages (--system-site-packages), so nothing
#    installed there is installed twice. When $(PYTHON) is itself a virtual or conda environment (one you
#    activated), that environment is used as it is.
# `make run PYTHON=/usr/bin/python3` picks the interpreter; .venv is rebuilt when it was made from another.
PYTHON ?= python3
VENV ?= .venv
PYTEST_ARGS ?=
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
APT := $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get

# The interpreter that runs posecrb: $(PYTHON) when it is an environment already, else $(VENV)'s.
PY := $(shell $(PYTHON) -c 'import os, sys; \
  print(sys.executable if sys.prefix != sys.base_prefix or os.path.isdir(os.path.join(sys.prefix, "conda-meta")) else "")' \
  2>/dev/null)
ifeq ($(PY),)
PY := $(VENV)/bin/python
OWN_VENV := 1
endif

SHELL := /bin/bash
.SHELLFLAGS := -euo pipefail -c
.ONESHELL:
.PHONY: install run lint test test-fast regress bench clean

install:
	@say() { echo "make: $$*" >&2; }
	command -v $(PYTHON) >/dev/null || { say "no interpreter '$(PYTHON)' (set PYTHON=/path/to/python3)"; exit 1; }
	# What apt must provide. A Debian-packaged interpreter needs python3.X-venv (ensurepip) for the venv
	# and python3.X-dev (Python.h) to compile scikit-sparse; any other interpreter brings its own.
	base=$$($(PYTHON) -c 'import os, sys; print(os.path.realpath(sys.executable))')
	ver=$$($(PYTHON) -c 'import sys; print("%d.%d" % sys.version_info[:2])')
	missing=""
	has() { dpkg-query -W -f='$${Status}' "$$1" 2>/dev/null | grep -q "ok installed"; }
	[ -f /usr/include/suitesparse/cholmod.h ] || missing="$$missing libsuitesparse-dev"
	has libopenblas0-pthread || missing="$$missing libopenblas0-pthread"
	if dpkg -S "$$base" >/dev/null 2>&1; then
	  $(PYTHON) -c 'import ensurepip' 2>/dev/null || missing="$$missing python$$ver-venv"
	  $(PYTHON) -c 'import os, sys, sysconfig; sys.exit(not os.path.isfile(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' \
	    || missing="$$missing python$$ver-dev"
	fi
	# scikit-sparse 0.4.16 has no wheel: pip compiles it (Cython and numpy come from pip) unless it imports already.
	py=$(PY); [ -x "$$py" ] || py=$(PYTHON)
	if ! "$$py" -c 'import sksparse.cholmod' 2>/dev/null && ! command -v cc >/dev/null; then
	  missing="$$missing gcc libc6-dev"
	fi
	if [ -n "$$missing" ]; then
	  say "installing$$missing (apt-get)"
	  $(APT) update -q && $(APT) install -y -q $$missing
	fi
ifdef OWN_VENV
	# (Re)create $(VENV) when absent or made from another interpreter.
	if [ "$$(cat $(VENV)/.posecrb-base 2>/dev/null)" != "$$base" ]; then
	  if [ -e $(VENV) ]; then
	    [ -f $(VENV)/pyvenv.cfg ] || { say "$(VENV) exists and is not a virtual environment; move it away"; exit 1; }
	    say "$(VENV) was made from another interpreter: rebuilding it from $$base"
	    rm -rf $(VENV)
	  fi
	  if $(PYTHON) -c 'import numpy' 2>/dev/null; then site=--system-site-packages; else site=; fi
	  say "creating $(VENV) from $$base (Python $$ver$${site:+, reusing its packages})"
	  $(PYTHON) -m venv $$site $(VENV)
	  echo "$$base" > $(VENV)/.posecrb-base
	fi
endif
	# (Re)install unless this very checkout is the installed posecrb and every dependency imports.
	$(PY) -I -c "import os, sys, posecrb, sksparse.cholmod, numba, threadpoolctl, pytest, hypothesis, mpmath, ruff, mypy; \
	  sys.exit(os.path.dirname(os.path.dirname(os.path.realpath(posecrb.__file__))) != os.path.realpath('.'))" \
	  2>/dev/null || { say "installing posecrb (editable, dev extras) into $$($(PY) -c 'import sys; print(sys.prefix)')"; \
	                   $(PY) -m pip install -q -e '.[dev]'; \
	                   $(PY) -m pip install -q 'gtsam>=4.2' 2>/dev/null \
	                     || say "gtsam not installable here: the GTSAM comparison tests will be skipped"; \
	                   say "the posecrb command: $$(dirname $(PY))/posecrb (or activate: . $$(dirname $(PY))/activate)"; }

# Recipes run silently (.ONESHELL: one shell per recipe); what matters is said on stderr, starting
# with which posecrb runs: `posecrb --version` names its package directory and interpreter.
run: install
	@$(PY) -m posecrb --version >&2
	# The manifest's missing datasets first (verified, progress bar); without network this says so once
	# and the tables use the datasets found, or the built-in synthetic graph when there is none.
	$(PY) -m posecrb -v datasets fetch --all --offline-ok >/dev/null
	$(PY) -m posecrb tables --all

# ruff (lint and import order) and mypy (types of the library, not the tests); configuration in
# pyproject.toml; part of `make test`, so CI runs both. .pre-commit-config.yaml runs the same on commit.
lint: install
	@$(PY) -m ruff check .
	$(PY) -m mypy

test: lint
	@$(PY) -m posecrb --version >&2
	$(PY) -m pytest -q $(PYTEST_ARGS)

# the suite without the long real-data and multi-process tests (marked `slow`)
test-fast: lint
	@$(PY) -m posecrb --version >&2
	$(PY) -m pytest -q -m "not slow" $(PYTEST_ARGS)

regress: install
	@$(PY) -m posecrb regress

bench: install
	@for f in benchmarks/*.py; do $(PY) $$f; done

clean:
	@rm -rf build dist *.egg-info .pytest_cache
