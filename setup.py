"""The one compiled part of avard: analyze's inner loops (core/allan/_kernels.c).

Everything else is in pyproject.toml. The extension is optional: where it cannot be built
(no compiler or no Python headers, as on a bare Raspberry Pi OS without python3-dev) the
install goes on and avard uses its numpy path (``avard.core.allan.kernels``), which gives
the same sums more slowly.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("avard.core.allan._kernels", ["core/allan/_kernels.c"],
                             extra_compile_args=["-O3"], optional=True)])
