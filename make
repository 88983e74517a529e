#!/usr/bin/env bash
# `make` on a machine that may not have it yet: installs what the Makefile needs first (Debian's make,
# python3 with venv, a C compiler; apt-get as root, or through sudo), then runs make with the same
# arguments. The README's quick start: ./make demo, ./make test.
set -euo pipefail
cd "$(dirname "$0")"
./scripts/install-system-deps base
exec make "$@"
