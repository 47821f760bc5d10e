# scengen service image: the HTTP API, and (same image) the Dask scheduler and workers.
# Build: docker compose build   (or: docker build -t scengen:local .)
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /opt/scengen

# Every dependency ships manylinux wheels (numpy, numba, lxml, pyarrow, psycopg[binary]),
# so no compiler is needed. The project metadata first, then the packages.
COPY pyproject.toml README.md constraints.txt ./
COPY app ./app
COPY datasets ./datasets
COPY riskcore ./riskcore
COPY sampler ./sampler
RUN pip install -c constraints.txt . \
    && useradd --create-home --uid 10001 --user-group scengen \
    && mkdir -p /data \
    && chown scengen:scengen /data

# A new named volume mounted at /data takes this ownership, so api and workers can write.
ENV SCENGEN_DATA_DIR=/data
USER scengen
WORKDIR /home/scengen
EXPOSE 8000

HEALTHCHECK --interval=10s --timeout=5s --start-period=60s --retries=5 \
    CMD ["python", "-c", "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/health', timeout=4)"]

CMD ["scengen", "serve", "--host", "0.0.0.0", "--port", "8000"]
