# Two commands do all set-up on a fresh machine (see README.md):
#   make run    install, then serve the bundled sample at http://127.0.0.1:8000
#   make test   install, then run the whole test suite
PYTHON ?= python3
HOST ?= 127.0.0.1
PORT ?= 8000
NPM_DIRS := $(wildcard web tests/app/node bench/geojsonvt)

.PHONY: run test install bench evaluate lint

.install-stamp: pyproject.toml $(foreach d,$(NPM_DIRS),$(wildcard $(d)/package-lock.json))
	$(PYTHON) -m pip install --quiet --disable-pip-version-check -e ".[dev]"
	@for d in $(NPM_DIRS); do \
	  if [ -f $$d/package.json ]; then echo "npm ci in $$d"; (cd $$d && npm ci --no-audit --no-fund --loglevel=error) || exit 1; fi; \
	done
	$(PYTHON) -m engine.warmup
	touch .install-stamp

install: .install-stamp

run: install
	ccsm serve --host $(HOST) --port $(PORT)

test: install
	$(PYTHON) -m pytest -q

bench: install
	$(PYTHON) bench/bench_engine.py
	$(PYTHON) bench/bench_tiles.py

evaluate: install
	ccsm evaluate data/sample/jacksboro_contours_20m.geojson --out out/evaluation

lint: install
	ruff check engine app tests bench
	mypy engine
