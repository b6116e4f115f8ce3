# AlphaFence developer commands. Every target installs what it needs first.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
MALTA  := ../shared/data/osm/malta-2018-08-27.osm.pbf

.PHONY: install demo test sitl-test bench fuzz lint clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/alphafence demo -o demo-out

test: $(STAMP)
	$(BIN)/pytest -q

sitl-test: $(STAMP)
	@$(BIN)/alphafence sitl --find >/dev/null  # on failure it prints how to get a binary
	$(BIN)/pytest -q -m sitl

bench: $(STAMP)
	$(BIN)/python -m bench --osm $(MALTA)

# >= 100,000 generated inputs across the readers (7 fuzz tests x 15,000); `make test` runs 60 each
fuzz: $(STAMP)
	ALPHAFENCE_FUZZ_EXAMPLES=15000 $(BIN)/pytest -q -p no:cacheprovider tests/test_fuzz_readers.py

lint: $(STAMP)
	$(BIN)/ruff check kit tests bench
	$(BIN)/ruff format --check kit tests bench

clean:
	rm -rf $(VENV) demo-out bench-out .pytest_cache .hypothesis
