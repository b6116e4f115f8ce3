# AlphaFence developer commands. Every target installs what it needs first.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
MALTA  := ../shared/data/osm/malta-2018-08-27.osm.pbf

# pygeoapi, the OGC API - Features server the live-source tests start on loopback (over a
# PostGIS table): a server beside the kit, in a virtual environment of its own
PYGEOAPI       := .venv-pygeoapi
PYGEOAPI_STAMP := $(PYGEOAPI)/.installed

.PHONY: install demo test test-oldest sitl-test navio2-test bench soak fuzz fuzz-atheris lint docs clean mutation mutation-ci

install: $(STAMP)

$(STAMP): pyproject.toml
	@echo "installing AlphaFence and its dependencies into $(VENV) (first run only, about a minute)..."
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

$(PYGEOAPI_STAMP):
	$(PYTHON) -m venv $(PYGEOAPI)
	$(PYGEOAPI)/bin/pip install --quiet --upgrade pip
	$(PYGEOAPI)/bin/pip install --quiet 'pygeoapi==0.21.0' 'psycopg2-binary>=2.9' 'geoalchemy2>=0.15'
	touch $@

demo: $(STAMP)
	$(BIN)/alphafence demo -o demo-out

# the suite on every core and one worker more (pytest-xdist; each SITL on its own ports and
# folder): a SITL test spends most of its time waiting on the simulated clock, so one more
# worker keeps the cores busy (on 2 cores, measured 2026-12-06 before the live-source tests:
# 10.7 minutes with 3 workers, 14.3 with 2); the
# SITL comes from ../shared/ardupilot-sitl when no other is found
WORKERS ?= $(shell $(PYTHON) -c "import os; print((os.cpu_count() or 1) + 1)")
# then the flights whose margin is a few metres at a speedup (marked alone: a monitor's few
# hundredths of a second of lateness on a loaded machine are metres there), one at a time
test: $(STAMP) $(PYGEOAPI_STAMP)
	$(BIN)/pytest -q -n $(WORKERS) --dist worksteal -m "not alone" --durations=25
	$(BIN)/pytest -q -m alone --durations=5

# the whole suite at the oldest versions the kit supports (pyproject.toml's floors, mostly
# Debian bookworm's): .venv-oldest from .ci/oldest-constraints.txt (needs Python 3.11, as
# bookworm's; pip's downloads cached under $ALPHAFENCE_CACHE, default ~/.cache/alphafence)
OLDEST       := .venv-oldest
OLDEST_STAMP := $(OLDEST)/.installed
OLDEST_CACHE ?= $(or $(ALPHAFENCE_CACHE),$(HOME)/.cache/alphafence)

$(OLDEST_STAMP): pyproject.toml .ci/oldest-constraints.txt
	$(PYTHON) -m venv $(OLDEST)
	PIP_CACHE_DIR=$(OLDEST_CACHE)/pip $(OLDEST)/bin/pip install --quiet --upgrade pip
	PIP_CACHE_DIR=$(OLDEST_CACHE)/pip $(OLDEST)/bin/pip install --quiet \
		-c .ci/oldest-constraints.txt -e '.[dev]'
	touch $@

test-oldest: $(OLDEST_STAMP) $(PYGEOAPI_STAMP)
	$(OLDEST)/bin/python -c "import numpy, scipy, shapely; print('oldest versions: numpy', \
		numpy.__version__, 'scipy', scipy.__version__, 'shapely', shapely.__version__)"
	@echo "oldest versions: the suite without the tests that drive only external parts (SITL, the browser), which make test runs"
	$(OLDEST)/bin/pytest -q -n auto --dist worksteal -m "not sitl and not browser" --durations=25

sitl-test: $(STAMP) $(PYGEOAPI_STAMP)
	@$(BIN)/alphafence sitl --find >/dev/null  # on failure it prints how to get a binary
	$(BIN)/pytest -q -n $(WORKERS) --dist worksteal -m "sitl and not alone"
	$(BIN)/pytest -q -m alone

# the safety-critical code broken on purpose, one small change at a time (mutmut 3; the
# targets and their tests in tests/mutation/targets.toml): fails on a break no test notices
# that tests/mutation/survivors.toml does not list as harmless; RECORD=1 writes the scores
mutation: $(STAMP)
	$(BIN)/pip install --quiet -e '.[mutation]'
	$(BIN)/python -m tests.mutation $(if $(RECORD),--record)

# CI's share: the targets whose module changed since tests/mutation/scores.json was recorded,
# or the fast decoder's alone when none did, each within 10 minutes
mutation-ci: $(STAMP)
	$(BIN)/pip install --quiet -e '.[mutation]'
	$(BIN)/python -m tests.mutation --changed --canary "fast decoder and signing" --budget 600

# a Navio2's OS (Debian armhf) under qemu-user, as root: the install in docs/onboard.md, the companion's
# unit tests and a flight against x86 SITL; not part of `make test` (see tests/navio2/run.sh)
navio2-test: $(STAMP)
	bash tests/navio2/run.sh

# mavsdk-grpc is measured beside the kit's links (bench/link_bench.py), not a dependency
bench: $(STAMP)
	$(BIN)/pip install --quiet 'mavsdk-grpc>=4.0.5'
	$(BIN)/python -m bench --osm $(MALTA)

# the monitor against SITL (speedup 10, simulated ADS-B) for 30 minutes: not part of `make bench`
soak: $(STAMP)
	@$(BIN)/alphafence sitl --find >/dev/null  # on failure it prints how to get a binary
	$(BIN)/python -m bench --osm $(MALTA) --only soak --soak-minutes 30

# >= 100,000 generated inputs across the readers (7 fuzz tests x 15,000) and as many again for
# what comes from the vehicle (6 x 15,000, plus hostile downloads); `make test` runs 60 each
fuzz: $(STAMP)
	ALPHAFENCE_FUZZ_EXAMPLES=15000 $(BIN)/pytest -q -p no:cacheprovider \
		tests/test_fuzz_readers.py tests/test_fuzz_vehicle_input.py

# coverage-guided (atheris/libFuzzer) byte mutation of every reader and the signed MAVLink link
ATHERIS_RUNS ?= 50000
ATHERIS_TARGETS := geojson ed269 osm fences plan waypoints rules mavlink
fuzz-atheris: $(STAMP)
	$(BIN)/pip install --quiet -e '.[fuzz]'
	@for t in $(ATHERIS_TARGETS); do \
		log=$${TMPDIR:-/tmp}/alphafence-atheris-$$t.log; \
		$(BIN)/python tests/atheris_fuzz.py $$t -runs=$(ATHERIS_RUNS) -max_len=4096 >$$log 2>&1 \
			|| { tail -25 $$log; echo "atheris $$t: crash (input saved as crash-*)"; exit 1; }; \
		echo "atheris $$t: $$(grep -E '^Done' $$log)"; \
	done

# the docs site into site/ (mkdocs.yml; `make test` builds it strictly and runs its commands)
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict -d site

lint: $(STAMP)
	$(BIN)/ruff check kit tests bench
	$(BIN)/ruff format --check kit tests bench

clean:
	rm -rf $(VENV) $(OLDEST) demo-out bench-out site .pytest_cache .hypothesis
