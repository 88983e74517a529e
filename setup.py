"""The compiled status decoder; optional: without a C compiler the package installs pure Python.

Everything else about the package is in pyproject.toml.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "overseer.codec._cstatus",
            ["exporter/overseer/codec/_cstatus.c"],
            extra_compile_args=["-O2", "-Wall", "-Wextra", "-Wno-unused-parameter"],
            optional=True,  # a failed build leaves overseer.codec.compiled falling back to pure Python
        )
    ]
)
