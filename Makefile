# The README's two commands: `make demo` and `make test`. Both create .venv on first use.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: setup demo test lint clean

$(STAMP): pyproject.toml scripts/system-deps.sh
	bash scripts/system-deps.sh
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[dev,osm,ifc]'
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/walkstream demo

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python scripts/typecheck.py

# pytest on every core (pytest-xdist): one worker per core; --dist loadfile keeps each test
# file on one worker, so a module's baked fixture is built once; the tests marked solo
# (asserting on real time) run alone afterwards, collected from the files that mark any
# (collecting every file again costs as much as a solo test) (docs/architecture.md, "A new test")
SOLO_FILES = $(shell grep -l 'mark\.solo' tests/test_*.py)
test: $(STAMP) lint
	$(BIN)/pytest -q -n auto --dist loadfile -m 'not solo'
	$(BIN)/pytest -q -m solo $(SOLO_FILES)

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache build *.egg-info
