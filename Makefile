# Set-up and main jobs. `make run` and `make test` install what is missing first:
# libsuitesparse-dev (apt-get; sudo only when not root) and this package with its dev extras.
PYTHON ?= python3
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
PYTEST_ARGS ?=

.PHONY: install run test regress bench clean

install:
	@if ! [ -f /usr/include/suitesparse/cholmod.h ]; then \
	  echo "installing libsuitesparse-dev (CHOLMOD headers and libraries)"; \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get update -q && \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -q libsuitesparse-dev; \
	fi
	@$(PYTHON) -c "import sksparse.cholmod, posecrb" 2>/dev/null && \
	  $(PYTHON) -m pip show -q posecrb >/dev/null 2>&1 && \
	  $(PYTHON) -c "import pytest, hypothesis, mpmath" 2>/dev/null || \
	  $(PYTHON) -m pip install -q -e '.[dev]'

run: install
	$(PYTHON) -m posecrb tables --all

test: install
	$(PYTHON) -m pytest -q $(PYTEST_ARGS)

regress: install
	$(PYTHON) -m posecrb regress

bench: install
	for f in benchmarks/*.py; do $(PYTHON) $$f || exit 1; done

clean:
	rm -rf build dist *.egg-info .pytest_cache
