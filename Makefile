# One entry point for users and CI. Every target installs first when needed.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test bench lint clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,bench]'
	@test -x $(BIN)/fixplan
	touch $(STAMP)

demo: install
	$(BIN)/fixplan validate fixplan/data/default.toml
	$(BIN)/fixplan solve --out out/demo-plan.json --force
	$(BIN)/fixplan classify --wrenches fixplan/data/demo_wrenches.csv
	$(BIN)/fixplan map --axes Fx,Tz --range -10:10,-1:1 --n 40 --out out/demo-map.png --force

test: install
	$(BIN)/python -m pytest -q tests
	FIXPLAN_SHORT=1 MPLBACKEND=Agg $(BIN)/python -m pytest -q --nbmake notebooks

bench: install
	$(BIN)/python benchmarks/run.py

lint: install
	$(BIN)/ruff check fixplan tests benchmarks
	$(BIN)/ruff format --check fixplan tests benchmarks
	$(BIN)/mypy

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache .mypy_cache
