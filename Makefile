# One entry point for users and CI. Every target installs first when needed.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install precompile demo test fuzz bench lint gallery gallery-notebooks lab clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	@# robots: example-robot-data (about 135 MB) for the library's Panda and UR5 problems, run in CI too
	$(BIN)/python -m pip install --quiet -e '.[dev,bench,robots]'
	@test -x $(BIN)/fixplan
	@# Headless Chromium for `fixplan view`'s browser test and `make gallery` (Debian's package; Playwright
	@# drives it, `playwright install` is never run). As root apt-get runs directly, else through sudo if present.
	@# A C compiler for the ahead-of-time kernels (numba.pycc, below), from Debian's gcc when none is there.
	@PKGS="$$(command -v chromium >/dev/null || echo chromium) $$(command -v cc >/dev/null || echo gcc)"; \
	if [ -n "$$(echo $$PKGS)" ]; then \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; elif command -v sudo >/dev/null; then SUDO=sudo; \
	  else echo "make install: $$PKGS missing and not root (browser tests skip; kernels stay just-in-time)" >&2; exit 0; fi; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$PKGS >/dev/null; fi
	@# Compile the numba kernels into their on-disk cache now (about 2 minutes), so that the first
	@# command after installing starts warm, then the 2D path's kernels ahead of time (fixplan/_aot*,
	@# loaded without numba); not fatal: a failure only means those runs compile or use the JIT.
	$(BIN)/python -m fixplan.cli.precompile --quiet || echo "make install: precompile failed (the first run will compile)" >&2
	@# Bytecode for the package (an editable install has none, and PYTHONDONTWRITEBYTECODE may forbid writing it later).
	$(BIN)/python -m compileall -q fixplan >/dev/null
	touch $(STAMP)

# Refill numba's cache and rebuild the ahead-of-time kernels after editing the package (make install
# does it once; until then an edited checkout runs numba's JIT: `fixplan --version` says which).
precompile: install
	$(BIN)/python -m fixplan.cli.precompile
	$(BIN)/python -m compileall -q fixplan >/dev/null

demo: install
	$(BIN)/fixplan validate fixplan/data/default.toml
	$(BIN)/fixplan solve --out out/demo-plan.json --force
	$(BIN)/fixplan classify --wrenches fixplan/data/demo_wrenches.csv
	$(BIN)/fixplan map --axes Fx,Tz --range -10:10,-1:1 --n 40 --out out/demo-map.png --force

# The suite runs in parallel processes (pytest-xdist), one per core up to four (TEST_WORKERS=1 for
# one): its time goes to single-threaded numerics and to waiting on subprocesses. --dist loadfile
# keeps each test file in one process, so that its module-scoped fixtures are built once.
TEST_WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); [ "$$n" -gt 4 ] && n=4; echo $$n)

test: install
	$(BIN)/python -m pytest -q --durations=15 -n $(TEST_WORKERS) --dist loadfile tests
	FIXPLAN_SHORT=1 MPLBACKEND=Agg $(BIN)/python -m pytest -q --nbmake notebooks

# The fuzz suite's long budget (tests/fuzz; `make test` runs a short derandomized one): 20x the
# examples with fresh seeds; FIXPLAN_FUZZ_SCALE=100 for a longer hunt. Failures found are kept in .hypothesis/.
fuzz: install
	FIXPLAN_FUZZ=long MPLBACKEND=Agg $(BIN)/python -m pytest -q -p no:cacheprovider tests/fuzz --hypothesis-show-statistics

bench: install
	$(BIN)/python benchmarks/run.py

# Pictures for the docs, regenerated from the default fixture.
gallery: install
	mkdir -p docs/gallery
	$(BIN)/fixplan solve --out out/gallery-plan.json --force
	$(BIN)/fixplan view --plan out/gallery-plan.json --out out/scene.html --force
	$(BIN)/python -m fixplan.present.browser out/scene.html docs/gallery/scene.png --width 900 --height 600
	@# Whitney's jamming diagram: the peg in the hole (peg-hole-mid) pushed down 1 N, lateral force x moment
	$(BIN)/fixplan map problems/peg-hole-mid.toml --axes Fx,Mz --range -0.6:0.6,-0.03:0.03 --wrench 0,-1,0 --n 60 --out out/gallery/jamming-map.png --force
	cp out/gallery/jamming-map.png docs/gallery/jamming-map.png
	@# The plan's figure (forces, gaps, wrench, contact states over time) that solve --report writes beside the report
	$(BIN)/fixplan solve --report out/gallery/plan.md --force
	cp out/gallery/plan.png docs/gallery/plan.png
	@# fixplan haptic: a scripted gizmo session and a jammed push, photographed in headless Chromium
	$(BIN)/python -m fixplan.interactive.gallery docs/gallery
	$(MAKE) gallery-notebooks

# The notebooks run in place, in full mode, with their outputs (text and PNG figures) stored, so
# that GitHub and a reader see the plots; volatile metadata is dropped so that re-running gives
# small diffs (tools/notebooks.py says what changes). `make test` runs them again without writing.
gallery-notebooks: install
	$(BIN)/python tools/notebooks.py

# JupyterLab on notebooks/, for this checkout's fixplan (editable install). It listens on
# 127.0.0.1 only and keeps Jupyter's token: open the URL with the token that it prints. As root
# (a container) Jupyter refuses to start unless told --allow-root, which changes nothing else.
lab: install
	$(BIN)/jupyter lab --ServerApp.ip=127.0.0.1 --ServerApp.root_dir=notebooks $$([ "$$(id -u)" = 0 ] && echo --allow-root)

lint: install
	$(BIN)/ruff check fixplan tests benchmarks tools
	$(BIN)/ruff format --check fixplan tests benchmarks tools
	$(BIN)/mypy

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache .mypy_cache
