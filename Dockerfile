# voxelastic: the job service (and the CLI) in a slim image, run as a non-root user.
#   docker build -t voxelastic .
#   docker run --rm -p 8000:8000 -v voxelastic-data:/data voxelastic        # API + local workers
#   docker compose up                                                       # API + Celery workers + Redis + PostgreSQL
# The same image runs a Celery worker: `celery -A service.celery_app worker` (see docker-compose.yml).
# CI builds this file and runs the bundled job inside the image (.ci/image).

FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
# Wheels of the dependencies first, from pyproject.toml alone: this layer stays cached while only
# the source changes (a rebuild then costs seconds instead of downloading ~300 MB of wheels).
RUN python -c "import tomllib; print('\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies']))" \
        > requirements.txt \
    && pip wheel --no-cache-dir --wheel-dir /wheels/deps -r requirements.txt
COPY engine ./engine
COPY schemas ./schemas
COPY service ./service
RUN pip wheel --no-cache-dir --no-deps --wheel-dir /wheels/project .

FROM python:3.11-slim
ENV PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    VOXELASTIC_CACHE_DIR=/home/voxelastic/.cache/voxelastic \
    VOXELASTIC_DATA_DIR=/data \
    VOXELASTIC_HOST=0.0.0.0 \
    VOXELASTIC_PORT=8000
# Shared libraries the wheels need but do not bundle. VTK renders the preview pictures off screen
# through Mesa's EGL (software; no display, no GPU). The X11 client library was what Taichi 1.7's
# core linked (without it no worker started, issue 18); gstaichi does not link it, and it stays
# until VTK's preview path is checked in an image without it. zlib is in the base already.
RUN apt-get update \
    && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends libx11-6 \
       libegl1 libegl-mesa0 libgl1-mesa-dri libxrender1 \
    && rm -rf /var/lib/apt/lists/*
RUN useradd --create-home --uid 1000 voxelastic \
    && mkdir -p /data /home/voxelastic/.cache/voxelastic \
    && chown voxelastic:voxelastic /data /home/voxelastic/.cache/voxelastic
COPY --from=build /wheels/deps /wheels/deps
RUN pip install --no-cache-dir /wheels/deps/*.whl && rm -rf /wheels/deps
COPY --from=build /wheels/project /wheels/project
RUN pip install --no-cache-dir --no-deps /wheels/project/*.whl && rm -rf /wheels/project
USER voxelastic
WORKDIR /home/voxelastic
# uploads, results and the SQLite job table (embedded default); share it between API and workers
VOLUME ["/data"]
EXPOSE 8000
# /health checks the database, the queue and that worker processes can start (503 otherwise);
# the slim image has no curl, Python it is
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/health' % os.environ.get('VOXELASTIC_PORT', '8000'), timeout=4)"]
ENTRYPOINT ["voxelastic"]
CMD ["serve"]
