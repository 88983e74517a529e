# The exporter, built from this repository with PyPI packages only.
FROM python:3.11-slim-bookworm

WORKDIR /src
COPY pyproject.toml README.md ./
COPY exporter ./exporter
RUN pip install --no-cache-dir . && rm -rf /src

RUN useradd --system --no-create-home overseer
USER overseer
EXPOSE 9849
ENTRYPOINT ["overseer"]
CMD ["run"]
