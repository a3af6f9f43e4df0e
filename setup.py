"""The compiled parts of avard: analyze's inner loops (core/allan/_kernels.c) and the
recording scan's frame loop (core/io/_framescan.c, linked against zlib for its CRC32).

Everything else is in pyproject.toml. The extensions are optional: where one cannot be built
(no compiler, no Python headers as on a bare Raspberry Pi OS without python3-dev, or no
zlib headers) the install goes on and avard uses its Python path (``avard.core.allan.kernels``;
the general frame reader of ``avard.core.io.recording``), which gives the same results more
slowly.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("avard.core.allan._kernels", ["core/allan/_kernels.c"],
                             extra_compile_args=["-O3"], optional=True),
                   Extension("avard.core.io._framescan", ["core/io/_framescan.c"],
                             extra_compile_args=["-O3"], libraries=["z"], optional=True)])
