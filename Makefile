# Two commands do all set-up on a fresh machine (see README.md):
#   make run    install into .venv/, then serve the bundled sample at http://127.0.0.1:8000
#   make test   install into .venv/, then ruff, import contracts, mypy, the web checks and the whole test suite
# Everything Python runs from the project's virtual environment .venv/ (made with $(PYTHON) -m venv), so a
# system Python that refuses installs (PEP 668, "externally-managed-environment") is never pip-installed into.
# Missing system tools (python3-venv, node/npm, chromium, QGIS's Python bindings) are installed with apt-get when run as root on
# Debian/Ubuntu; otherwise make stops and says which command to run.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
HOST ?= 127.0.0.1
PORT ?= 8000
# The browser tests launch this binary (tests/browser/chromium_launch.py); override only to test the check.
CHROMIUM ?= /usr/bin/chromium
PYTEST_ARGS ?=
NPM_DIRS := $(wildcard web web/plugin tests/app/node bench/geojsonvt)

.PHONY: run test install bench evaluate lint need-node need-chromium need-qgis need-rdata
# Steps install system packages and share one venv: never run them side by side (make -j).
.NOTPARALLEL:

# $(call need,CHECK,PACKAGES,WHAT): if the shell command CHECK fails, install the Debian PACKAGES when root
# (and apt-get exists), else stop with the command to run. No commas in the arguments.
define need
@if ! { $(1); }; then \
  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
    echo "$(3) is missing: apt-get install $(2)"; \
    export DEBIAN_FRONTEND=noninteractive; \
    apt-get update -qq && apt-get install -y -qq $(2) >/dev/null || exit 1; \
    { $(1); } || { echo "error: $(3) is still missing after apt-get install $(2)" >&2; exit 1; }; \
  else \
    echo "error: $(3) is missing. Install it, then run make again:" >&2; \
    echo "    sudo apt-get install $(2)" >&2; \
    exit 1; \
  fi; \
fi
endef

need-node:
	$(call need,command -v node >/dev/null 2>&1 && command -v npm >/dev/null 2>&1,nodejs npm,Node.js (node and npm))

need-chromium:
	$(call need,[ -x "$(CHROMIUM)" ],chromium fonts-dejavu-core,Chromium ($(CHROMIUM)) for the browser tests)

# The QGIS client test runs Debian's own /usr/bin/python3, which sees the bindings (the venv does not).
need-qgis:
	$(call need,/usr/bin/python3 -c "import qgis.core" >/dev/null 2>&1,--no-install-recommends python3-qgis,QGIS's Python bindings (python3-qgis) for the QGIS client test)

# The real-terrain tests (tests/real_dems.py) read DEMs that Debian's R packages ship, through Rscript.
need-rdata:
	$(call need,[ -f /usr/lib/R/site-library/terra/ex/elev.tif ] && [ -f /usr/lib/R/site-library/fields/data/RMelevation.rda ] && command -v Rscript >/dev/null 2>&1,--no-install-recommends r-cran-terra r-cran-fields,The real DEMs of R's terra and fields packages (r-cran-terra r-cran-fields))

# The virtual environment. Debian's python3 makes a venv only with python3-venv (ensurepip) installed.
$(BIN)/pip:
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found; install Python >= 3.11 or run make PYTHON=/path/to/python3" >&2; exit 1; }
	$(call need,$(PYTHON) -c "import ensurepip" >/dev/null 2>&1,python3-venv,Python's venv support (ensurepip) for $(PYTHON))
	$(PYTHON) -m venv $(VENV)

# The Python packages' versions the suite last passed with (pip freeze); empty (make install CONSTRAINTS=): pip chooses.
CONSTRAINTS ?= constraints.txt

# Reinstalls only when the venv, pyproject.toml, the constraints or an npm manifest changes.
# Each one-time step says what it does and about how long it takes first (a fresh make run is ~2.5 minutes).
.install-stamp: $(BIN)/pip pyproject.toml $(CONSTRAINTS) $(foreach d,$(NPM_DIRS),$(wildcard $(d)/package.json $(d)/package-lock.json)) | need-node
	@echo "installing Python packages into $(VENV) (one time, ~1 min)"
	$(BIN)/python -m pip install --quiet --disable-pip-version-check $(if $(CONSTRAINTS),-c $(CONSTRAINTS)) -e ".[dev]"
	@for d in $(NPM_DIRS); do \
	  if [ -f $$d/package.json ]; then echo "installing JavaScript packages in $$d: npm ci (one time, ~15 s)"; (cd $$d && npm ci --no-audit --no-fund --loglevel=error) || exit 1; fi; \
	done
	@echo "compiling numba kernels (one time, ~45 s)"
	$(BIN)/python -m engine.warmup
	touch .install-stamp
	@echo "installed: later runs start at once"

install: .install-stamp

run: install
	$(BIN)/ccsm serve --host $(HOST) --port $(PORT)

# Never passes with a tool missing: node and chromium are required (the tests fail rather than skip without
# them), and pytest's status 5 (no tests collected) fails make like any other non-zero status.
# Tools are checked first, so a missing one stops make before the long install.
test: need-node need-chromium need-qgis need-rdata install lint
	cd web && npm run --if-present test
	cd web/plugin && npm run --if-present test
	$(BIN)/python -m pytest -q $(PYTEST_ARGS)

bench: install
	$(BIN)/python bench/bench_engine.py
	$(BIN)/python bench/bench_tiles.py

evaluate: install
	$(BIN)/ccsm evaluate data/sample/jacksboro_contours_20m.geojson --out out/evaluation

# ruff (with a complexity limit), the import-linter layering contracts and mypy (pydantic plugin) on engine
# and app: all part of make test.
lint: install
	$(BIN)/ruff check engine app tests bench
	$(BIN)/lint-imports
	$(BIN)/mypy
