# The pdeanim service image: one image for the API (`pdeanim serve`), the worker (`pdeanim worker`) and the
# migration step (`pdeanim serve --migrate-only`); chosen by the compose service's command.
FROM python:3.11-slim-bookworm
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 PDEANIM_DATA_DIR=/data
RUN apt-get update && apt-get install -y --no-install-recommends libgomp1 && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY pyproject.toml setup.py README.md alembic.ini requirements.lock requirements-service.lock ./
RUN pip install -r requirements-service.lock
COPY pdeanim ./pdeanim
COPY service ./service
COPY worker ./worker
RUN pip install --no-deps . && useradd --create-home --uid 1000 pdeanim && mkdir -p /data && chown pdeanim /data
USER pdeanim
EXPOSE 8000
CMD ["pdeanim", "serve", "--host", "0.0.0.0", "--port", "8000", "--no-migrate"]
