# mapqual: one image for the API, the Celery workers and the viewer.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    NUMBA_CACHE_DIR=/tmp/numba-cache

WORKDIR /app
COPY pyproject.toml README.md alembic.ini ./
COPY mapqual ./mapqual
COPY worker ./worker
COPY backend ./backend
COPY frontend ./frontend
COPY migrations ./migrations
COPY worlds ./worlds
# Editable, so that the migrations/ folder beside the packages is found at run time.
RUN pip install -e . && useradd --create-home --uid 1000 mapqual && mkdir -p /data/runs \
    && chown -R mapqual /data /app
USER mapqual
EXPOSE 8000
CMD ["mapqual", "serve", "--host", "0.0.0.0", "--port", "8000"]
