# endeff_ros developer entry points. Everything installs into .venv from PyPI.
#   make run    set up, generate the default synthetic data, run the main job, print scores
#   make test   set up and run the whole test suite
#   make bench  timing benchmarks (JSON)
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DATA := data/synth
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp
export FASTRTPS_DEFAULT_PROFILES_FILE ?= $(CURDIR)/config/fastdds_shm.xml
export FASTDDS_DEFAULT_PROFILES_FILE ?= $(CURDIR)/config/fastdds_shm.xml

.PHONY: venv run test bench data lint clean eval

venv: $(STAMP)

$(STAMP): requirements.txt setup.py
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --disable-pip-version-check -r requirements.txt
	$(BIN)/pip install --quiet --disable-pip-version-check --no-deps -e .
	touch $(STAMP)

$(DATA)/.done: $(STAMP)
	$(BIN)/endeff synth --out $(DATA) --storage mcap
	touch $@

data: $(DATA)/.done

run: $(DATA)/.done
	$(BIN)/python -m tools.demo --data $(DATA)

test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/python -m tools.bench --json bench.json

lint: $(STAMP)
	$(BIN)/ruff check endeff_ros test tools

clean:
	rm -rf build install log $(VENV) data

# The committed evaluation report (docs/eval): both estimators on the full synthetic set.
eval: $(DATA)/.done
	$(BIN)/endeff eval $(DATA)/mcap --json docs/eval/report.json --plots docs/eval --jobs 2
