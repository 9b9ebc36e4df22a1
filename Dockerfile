# voxelastic: the CLI (and, once it lands, the service) in a slim image, run as a non-root user.
FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY engine ./engine
COPY schemas ./schemas
COPY service ./service
RUN pip wheel --no-cache-dir --wheel-dir /wheels .

FROM python:3.11-slim
ENV PYTHONUNBUFFERED=1 \
    TI_SKIP_VERSION_CHECK=ON \
    VOXELASTIC_CACHE_DIR=/home/voxelastic/.cache/voxelastic
RUN useradd --create-home --uid 1000 voxelastic
COPY --from=build /wheels /wheels
RUN pip install --no-cache-dir /wheels/*.whl && rm -rf /wheels
USER voxelastic
WORKDIR /home/voxelastic
ENTRYPOINT ["voxelastic"]
CMD ["--help"]
