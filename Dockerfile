# voxelastic: the job service (and the CLI) in a slim image, run as a non-root user.
#   docker build -t voxelastic .
#   docker run --rm -p 8000:8000 -v voxelastic-data:/data voxelastic        # API + local workers
#   docker compose up                                                       # API + Celery workers + Redis + PostgreSQL
# The same image runs a Celery worker: `celery -A service.celery_app worker` (see docker-compose.yml).

FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY engine ./engine
COPY schemas ./schemas
COPY service ./service
# wheels of the project and of every dependency; the runtime stage installs them without a compiler
RUN pip wheel --no-cache-dir --wheel-dir /wheels .

FROM python:3.11-slim
ENV PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    TI_SKIP_VERSION_CHECK=ON \
    VOXELASTIC_CACHE_DIR=/home/voxelastic/.cache/voxelastic \
    VOXELASTIC_DATA_DIR=/data \
    VOXELASTIC_HOST=0.0.0.0 \
    VOXELASTIC_PORT=8000
RUN useradd --create-home --uid 1000 voxelastic \
    && mkdir -p /data /home/voxelastic/.cache/voxelastic \
    && chown voxelastic:voxelastic /data /home/voxelastic/.cache/voxelastic
COPY --from=build /wheels /wheels
RUN pip install --no-cache-dir /wheels/*.whl && rm -rf /wheels
USER voxelastic
WORKDIR /home/voxelastic
# uploads, results and the SQLite job table (embedded default); share it between API and workers
VOLUME ["/data"]
EXPOSE 8000
# /health checks the database and the queue; the slim image has no curl, Python it is
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/health' % os.environ.get('VOXELASTIC_PORT', '8000'), timeout=4)"]
ENTRYPOINT ["voxelastic"]
CMD ["serve"]
