"""The compiled status decoder, deflater and field hashes; optional: without a C compiler, pure Python.

OVERSEER_REQUIRE_COMPILED=1 makes it required, so a build that must ship it (the image's) fails instead.
Everything else about the package is in pyproject.toml.
"""

import os

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "overseer.codec._cstatus",
            ["exporter/overseer/codec/_cstatus.c"],
            extra_compile_args=["-O2", "-Wall", "-Wextra", "-Wno-unused-parameter"],
            # A failed build leaves overseer.codec.compiled falling back to pure Python.
            optional=os.environ.get("OVERSEER_REQUIRE_COMPILED") != "1",
        ),
        Extension(
            "overseer.fleet._cdeflate",
            ["exporter/overseer/fleet/_cdeflate.c"],
            libraries=["z"],
            extra_compile_args=["-O2", "-Wall", "-Wextra", "-Wno-unused-parameter"],
            # Without it, overseer.fleet.deflated falls back to Python's zlib module.
            optional=os.environ.get("OVERSEER_REQUIRE_COMPILED") != "1",
        ),
        Extension(
            "overseer.fleet._cstamps",
            ["exporter/overseer/fleet/_cstamps.c"],
            extra_compile_args=["-O2", "-Wall", "-Wextra", "-Wno-unused-parameter"],
            # Without it, overseer.fleet.stamps hashes the same fields by map and zip.
            optional=os.environ.get("OVERSEER_REQUIRE_COMPILED") != "1",
        ),
    ]
)
