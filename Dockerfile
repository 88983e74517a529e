# The exporter, built from this repository with PyPI packages only.
FROM python:3.11-slim-bookworm

WORKDIR /src
COPY pyproject.toml setup.py README.md ./
COPY exporter ./exporter
# The slim image has no C compiler: the optional compiled status decoder is not built and the exporter
# decodes in pure Python (it says so in its log and in overseer_build_info{codec="python"}).
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
