# Set-up and main jobs. `make run` and `make test` install what is missing first:
# libsuitesparse-dev and libopenblas0-serial (apt-get; sudo only when not root) and this package with its dev extras.
PYTHON ?= python3
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
PYTEST_ARGS ?=

.PHONY: install run lint test test-fast regress bench clean

install:
	@missing=""; \
	  [ -f /usr/include/suitesparse/cholmod.h ] || missing="$$missing libsuitesparse-dev"; \
	  dpkg-query -W -f='$${Status}' libopenblas0-serial 2>/dev/null | grep -q "ok installed" || \
	    missing="$$missing libopenblas0-serial"; \
	  if [ -n "$$missing" ]; then \
	    echo "installing$$missing (CHOLMOD; an optimised BLAS for its supernodal factorizations)"; \
	    $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get update -q && \
	    $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -q $$missing; \
	  fi
	@# (re)install unless this very checkout is the installed posecrb and every dependency imports
	@$(PYTHON) -I -c "import os, sys, posecrb, sksparse.cholmod, numba, threadpoolctl, pytest, hypothesis, mpmath, ruff; \
	  sys.exit(os.path.dirname(os.path.dirname(os.path.realpath(posecrb.__file__))) != os.path.realpath('.'))" \
	  2>/dev/null || $(PYTHON) -m pip install -q -e '.[dev]'

run: install
	$(PYTHON) -m posecrb tables --all

# ruff: lint and import order (configuration in pyproject.toml); part of `make test`, so CI runs it.
lint: install
	$(PYTHON) -m ruff check .

test: lint
	$(PYTHON) -m pytest -q $(PYTEST_ARGS)

# the suite without the long real-data and multi-process tests (marked `slow`)
test-fast: lint
	$(PYTHON) -m pytest -q -m "not slow" $(PYTEST_ARGS)

regress: install
	$(PYTHON) -m posecrb regress

bench: install
	for f in benchmarks/*.py; do $(PYTHON) $$f || exit 1; done

clean:
	rm -rf build dist *.egg-info .pytest_cache
