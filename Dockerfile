# The exporter, built from this repository with PyPI packages only.
FROM python:3.11-slim-bookworm

WORKDIR /src
COPY pyproject.toml README.md ./
COPY exporter ./exporter
RUN pip install --no-cache-dir . && rm -rf /src

RUN useradd --system --no-create-home overseer \
    && mkdir -p /var/lib/overseer && chown overseer /var/lib/overseer
USER overseer
# The event history (overseer-events.db) is written to the working directory: mount a volume here to keep it.
WORKDIR /var/lib/overseer
VOLUME /var/lib/overseer
EXPOSE 9849
ENTRYPOINT ["overseer"]
CMD ["run"]
