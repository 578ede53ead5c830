# syntax=docker/dockerfile:1
# ccsm tile service: multi-stage build, non-root user, store on a volume, HEALTHCHECK on /healthz.

# --- build stage: wheels of the project and its dependencies -------------------------------------------
FROM python:3.11-slim AS build
ENV PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_CACHE_DIR=1
WORKDIR /src
COPY pyproject.toml README.md constraints.txt ./
COPY engine ./engine
COPY app ./app
RUN python -m venv /opt/venv \
 && /opt/venv/bin/pip install --upgrade pip \
 && /opt/venv/bin/pip install -c constraints.txt .

# --- web stage: the page's npm dependencies (MapLibre GL JS, the morph plugin's decoders) --------------------
FROM node:20-slim AS web
WORKDIR /web
COPY web/package.json web/package-lock.json ./
RUN npm ci --omit=dev --no-audit --no-fund

# --- runtime stage -----------------------------------------------------------------------------------------
FROM python:3.11-slim AS runtime
ENV PATH=/opt/venv/bin:$PATH \
    PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    NUMBA_CACHE_DIR=/tmp/numba \
    CCSM_STORE_PATH=/data/ccsm.sqlite \
    CCSM_WEB_DIR=/app/web
# The label glyphs (/fonts/...) are drawn from DejaVu Sans (CCSM_FONT_PATH's default).
RUN apt-get update \
 && apt-get install -y --no-install-recommends fonts-dejavu-core \
 && rm -rf /var/lib/apt/lists/*
RUN groupadd --system --gid 10001 ccsm \
 && useradd --system --uid 10001 --gid ccsm --home-dir /app --shell /usr/sbin/nologin ccsm \
 && mkdir -p /data /app \
 && chown ccsm:ccsm /data
COPY --from=build /opt/venv /opt/venv
WORKDIR /app
# The engine finds the bundled sample next to its package: keep the repository layout.
COPY --chown=ccsm:ccsm engine ./engine
COPY --chown=ccsm:ccsm app ./app
COPY --chown=ccsm:ccsm data/sample ./data/sample
COPY --chown=ccsm:ccsm web ./web
COPY --from=web --chown=ccsm:ccsm /web/node_modules ./web/node_modules
USER ccsm
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=5s --start-period=30s --retries=3 \
  CMD ["python", "-c", "import urllib.request,sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4).status == 200 else 1)"]
CMD ["ccsm", "serve", "--host", "0.0.0.0", "--port", "8000"]
