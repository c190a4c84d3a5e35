# Two commands on a fresh machine (Python 3.11): `make reproduce` and `make test`.
# Each creates .venv from environment.txt first when it is missing or out of date.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
ARGS ?=

.PHONY: reproduce test bench clean

$(VENV)/.installed: environment.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r environment.txt
	touch $@

reproduce: $(VENV)/.installed  ## batch reproduction on the embedded synthetic default -> reports/
	$(PY) -m dynslam_lite reproduce $(ARGS)

test: $(VENV)/.installed  ## the test suite
	$(PY) -m pytest -q $(ARGS)

bench: $(VENV)/.installed  ## speed and memory figures (ms/frame per stage, peak memory)
	$(PY) -m dynslam_lite bench $(ARGS)

clean:
	rm -rf build .pytest_cache
