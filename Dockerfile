# The exporter, built from this repository with PyPI packages only, in two stages: a compiler builds the
# wheel with the compiled status decoder, deflater and field hashes, and the slim runtime installs it with
# the locked dependencies.

# Build stage: the full image has gcc, Python's headers and zlib's. scripts/build-wheel fails unless the C
# extensions built, so the runtime never falls back to pure Python.
FROM python:3.11-bookworm AS build
RUN python3 -m venv /build
ENV PATH=/build/bin:$PATH
WORKDIR /src
COPY pyproject.toml setup.py README.md ./
COPY requirements ./requirements
COPY scripts/build-wheel ./scripts/build-wheel
COPY exporter ./exporter
RUN scripts/build-wheel /dist

# Runtime stage: no compiler. The locked tools and runtime dependencies (hashes checked), then the wheel
# with nothing left to resolve; the exporter says overseer_build_info{codec="compiled"}.
FROM python:3.11-slim-bookworm
COPY requirements/tools.txt requirements/runtime.txt /tmp/requirements/
COPY --from=build /dist /tmp/dist
RUN pip install --no-cache-dir --require-hashes -r /tmp/requirements/tools.txt \
    && pip install --no-cache-dir --require-hashes -r /tmp/requirements/runtime.txt \
    && pip install --no-cache-dir --no-deps /tmp/dist/overseer-*.whl \
    && pip check \
    && python3 -c "from overseer.codec import compiled; assert compiled.AVAILABLE, 'no compiled decoder'" \
    && python3 -c "from overseer.fleet import deflated; assert deflated.COMPILED, 'no compiled deflater'" \
    && python3 -c "from overseer.fleet import stamps; assert stamps.COMPILED, 'no compiled field hashes'" \
    && rm -rf /tmp/requirements /tmp/dist

RUN useradd --system --no-create-home overseer \
    && mkdir -p /var/lib/overseer && chown overseer /var/lib/overseer
USER overseer
# The event history (overseer-events.db) is written to the working directory: mount a volume here to keep it.
WORKDIR /var/lib/overseer
VOLUME /var/lib/overseer
EXPOSE 9849
ENTRYPOINT ["overseer"]
CMD ["run"]
