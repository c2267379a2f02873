# Set-up and main jobs. `make run` and `make test` first install what is missing:
#  * with apt-get (through sudo only when not root): libsuitesparse-dev and libopenblas0-pthread (the
#    threaded OpenBLAS: CHOLMOD's supernodal factorizations use every core); for a
#    Debian-packaged interpreter its venv and header packages (python3.X-venv, python3.X-dev); gcc when
#    scikit-sparse has to be compiled and there is no C compiler;
#  * the virtual environment .venv, made from $(PYTHON), with every runtime and development dependency
#    at the versions of the lock (requirements/lock.txt, hashes checked) and this checkout installed
#    in it (editable). Nothing is ever installed into $(PYTHON) itself: a Debian system interpreter
#    refuses (PEP 668, "externally managed") and a pyenv or conda base interpreter serves other
#    projects. The lock covers CPython $(LOCK_PYTHON); with another Python, .venv is installed from the
#    version ranges of pyproject.toml instead, and make says so. When $(PYTHON) is itself a virtual or
#    conda environment (one you activated), that environment is used as it is: what is missing is
#    installed there from the ranges, not the lock, and make says so.
# `make run PYTHON=/usr/bin/python3` picks the interpreter; .venv is rebuilt when it was made from another.
# `make lock` regenerates the lock (UPGRADE=1: newest releases the ranges admit); `make test-latest` runs the
# suite in a scratch environment with the newest releases instead of the lock.
PYTHON ?= python3
VENV ?= .venv
PYTEST_ARGS ?=
UPGRADE ?=
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
APT := $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get

# The lock: every package of every extra plus what scikit-sparse's build needs, with hashes, for this Python.
LOCK := requirements/lock.txt
BUILD_LOCK := requirements/build-lock.txt
LOCK_PYTHON := 3.11
LOCK_FLAGS := --python-version $(LOCK_PYTHON) --python-platform linux --generate-hashes \
              --custom-compile-command "make lock" $(if $(UPGRADE),--upgrade)

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
.PHONY: system install run lint test test-fast test-latest lock regress bench bench-quick bench-report docs clean

# What apt must provide. A Debian-packaged interpreter needs python3.X-venv (ensurepip) for a venv and
# python3.X-dev (Python.h) to compile scikit-sparse; any other interpreter brings its own.
system:
	@say() { echo "make: $$*" >&2; }
	command -v $(PYTHON) >/dev/null || { say "no interpreter '$(PYTHON)' (set PYTHON=/path/to/python3)"; exit 1; }
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
	# scikit-sparse has no wheel: pip compiles it unless it imports already.
	py=$(PY); [ -x "$$py" ] || py=$(PYTHON)
	if ! "$$py" -c 'import sksparse.cholmod' 2>/dev/null && ! command -v cc >/dev/null; then
	  missing="$$missing gcc libc6-dev"
	fi
	if [ -n "$$missing" ]; then
	  say "installing$$missing (apt-get)"
	  $(APT) update -q && $(APT) install -y -q $$missing
	fi

install: system
	@say() { echo "make: $$*" >&2; }
	base=$$($(PYTHON) -c 'import os, sys; print(os.path.realpath(sys.executable))')
	ver=$$($(PYTHON) -c 'import sys; print("%d.%d" % sys.version_info[:2])')
ifdef OWN_VENV
	# (Re)create $(VENV) when absent, made from another interpreter, or seeing the interpreter's own
	# packages (an older layout): the lock alone decides what is in it.
	if [ "$$(cat $(VENV)/.posecrb-base 2>/dev/null)" != "$$base" ] \
	   || grep -qs '^include-system-site-packages *= *true' $(VENV)/pyvenv.cfg; then
	  if [ -e $(VENV) ]; then
	    [ -f $(VENV)/pyvenv.cfg ] || { say "$(VENV) exists and is not a virtual environment; move it away"; exit 1; }
	    say "rebuilding $(VENV) from $$base"
	    rm -rf $(VENV)
	  fi
	  say "creating $(VENV) from $$base (Python $$ver)"
	  $(PYTHON) -m venv $(VENV)
	  echo "$$base" > $(VENV)/.posecrb-base
	fi
	if [ "$$ver" = "$(LOCK_PYTHON)" ]; then
	  # Reinstall when the lock or pyproject.toml changed since the last install, or when the posecrb
	  # installed is not this checkout.
	  stamp=$$(cat $(LOCK) $(BUILD_LOCK) pyproject.toml | sha256sum | cut -c1-16)
	  if [ "$$(cat $(VENV)/.posecrb-lock 2>/dev/null)" != "$$stamp" ] \
	     || ! $(PY) -I -c "import os, sys, posecrb; sys.exit(os.path.dirname(os.path.dirname(os.path.realpath(posecrb.__file__))) != os.path.realpath('.'))" 2>/dev/null; then
	    say "installing the locked versions ($(LOCK)) into $(VENV)"
	    rm -f $(VENV)/.posecrb-lock
	    # scikit-sparse is compiled against the locked numpy and Cython (no isolated build environment).
	    $(PY) -m pip install -q --disable-pip-version-check --require-hashes --no-deps -r $(BUILD_LOCK)
	    $(PY) -m pip install -q --disable-pip-version-check --require-hashes --no-deps --no-build-isolation -r $(LOCK)
	    $(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	    $(PY) -m pip check >/dev/null || { $(PY) -m pip check >&2; say "the lock is inconsistent: run make lock"; exit 1; }
	    echo "$$stamp" > $(VENV)/.posecrb-lock
	    say "the posecrb command: $(VENV)/bin/posecrb (or activate: . $(VENV)/bin/activate)"
	  fi
	  exit 0
	fi
	say "the lock covers Python $(LOCK_PYTHON), not $$ver: installing from the version ranges of pyproject.toml"
endif
	# Not the lock: an environment you activated, or a Python the lock does not cover. Install what is
	# missing from the ranges of pyproject.toml, and say that these are not the locked versions.
	$(PY) -I -c "import os, sys, posecrb, sksparse.cholmod, numba, threadpoolctl, pytest, hypothesis, mpmath, ruff, mypy, sphinx; \
	  sys.exit(os.path.dirname(os.path.dirname(os.path.realpath(posecrb.__file__))) != os.path.realpath('.'))" \
	  2>/dev/null || { say "installing posecrb (editable, dev and docs extras) into $$($(PY) -c 'import sys; print(sys.prefix)')"; \
	                   $(PY) -m pip install -q -e '.[dev,docs]'; \
	                   $(PY) -m pip install -q 'gtsam>=4.2' 2>/dev/null \
	                     || say "gtsam not installable here: the GTSAM comparison tests will be skipped"; }
	say "note: $$($(PY) -c 'import sys; print(sys.prefix)') has versions from the ranges of pyproject.toml, not the locked ones ($(LOCK))"

# Regenerate the lock from pyproject.toml's ranges (every extra) and requirements/build.in, for CPython
# $(LOCK_PYTHON) on Linux, with uv's pip compile (from the dev extra). Pins already in the lock are kept
# where the ranges still admit them; UPGRADE=1 takes the newest releases instead.
lock: install
	@$(PY) -m uv pip compile -q pyproject.toml requirements/build.in --all-extras $(LOCK_FLAGS) -o $(LOCK)
	$(PY) -m uv pip compile -q requirements/build.in --constraint $(LOCK) $(LOCK_FLAGS) -o $(BUILD_LOCK)
	for f in $(LOCK) $(BUILD_LOCK); do
	  sed -i '2a # Covers CPython $(LOCK_PYTHON) on Linux (resolved for x86_64; every file of each pinned release is hashed).' "$$f"
	done
	echo "make: wrote $(LOCK) and $(BUILD_LOCK) (CPython $(LOCK_PYTHON), Linux)" >&2

# The suite in a scratch environment with the newest releases that pyproject.toml's ranges admit (not the
# lock): lint, tests and the docs build. Exception: scikit-sparse stays on 0.4.x (the range's <0.5), because
# 0.5 and later need SuiteSparse >= 7 and Debian 12 ships 5. The environment is removed afterwards; the
# versions it used are printed first.
test-latest: system
	@scratch=$$(mktemp -d "$${TMPDIR:-/tmp}/posecrb-latest.XXXXXX")
	trap 'rm -rf "$$scratch"' EXIT
	$(PYTHON) -m venv "$$scratch/venv"
	py="$$scratch/venv/bin/python"
	echo "make: installing the newest releases into $$scratch/venv" >&2
	"$$py" -m pip install -q --disable-pip-version-check --upgrade pip
	"$$py" -m pip install -q -e '.[dev,docs,gtsam]'
	echo "make: newest versions used:" >&2
	"$$py" -m pip list --format=freeze --exclude-editable | sed 's/^/  /' >&2
	"$$py" -m ruff check .
	"$$py" -m mypy
	"$$py" -m pytest -q -p no:cacheprovider $(PYTEST_ARGS)

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

# The benchmark suite (benchmarks/run.py): the in-process asv suite over the SE-Sync datasets ($POSECRB_DATA)
# and the scaling grids, the whole-process comparisons through hyperfine (posecrb's commands, and the peers
# SE-Sync C++, GTSAM and MAC when $SESYNC_BIN / gtsam / $POSECRB_MAC_PYTHON are there), then the report's tables
# in .bench/report. `make bench` installs hyperfine (apt) when it is missing; `make test` does not need it.
bench: install
	@command -v hyperfine >/dev/null || { echo "make: installing hyperfine (apt-get)" >&2; \
	  $(APT) update -q && $(APT) install -y -q hyperfine; }
	$(PY) benchmarks/run.py

# Every benchmark once on small inputs, in a few minutes: a broken benchmark fails (the test suite runs the same,
# tests/benchmarks/test_benchmarks.py, so CI does too). Comparisons whose program is missing say so and are skipped.
bench-quick: install
	@$(PY) benchmarks/run.py --quick

# The performance page's tables and scaling figure from the suite's last results (.bench), into .bench/report,
# and the page itself: docs/performance.md and docs/figures/scaling.png.
bench-report: install
	@$(PY) benchmarks/report.py --page docs/performance.md

# The documentation site into docs/_build/html: Sphinx with warnings as errors, offline (no
# intersphinx, nothing fetched at build time). Its packages are the `docs` extra, installed here
# when one of them is missing.
docs: install
	@$(PY) -c 'import sphinx, myst_parser, pydata_sphinx_theme, numpydoc, sphinx_click' 2>/dev/null \
	  || { echo "make: installing the docs extra" >&2; $(PY) -m pip install -q -e '.[docs]'; }
	$(PY) -m sphinx -W --keep-going -E -q -b html docs docs/_build/html
	echo "make: the site is in docs/_build/html/index.html" >&2

clean:
	@rm -rf build dist *.egg-info .pytest_cache docs/_build .bench/quick
