# pibr in a container: server, relay and client all run from this image (see docker-compose.yml).
# OpenGL runs headless through Mesa's EGL (llvmpipe on the CPU, or the host GPU's Mesa driver).
FROM python:3.11-slim

RUN apt-get update \
 && apt-get install -y --no-install-recommends libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libgbm1 \
 && rm -rf /var/lib/apt/lists/*

# The whole build context (.dockerignore leaves out tests, docs, outputs and caches): a regular,
# non-editable install that finds its packages and data itself, as a newcomer's `pip install .`.
WORKDIR /opt/pibr
COPY . .
RUN pip install --no-cache-dir . && pibr --version

# LoD proxies and other caches survive container restarts when /cache is a volume.
ENV PIBR_CACHE_DIR=/cache
WORKDIR /work
ENTRYPOINT ["pibr"]
CMD ["--help"]
