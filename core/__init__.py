"""avard.core: numerics, noise models, simulation, file formats and reports.

Arrays in, arrays out. Nothing here touches hardware or sockets, and nothing here imports
``avard.daemon``.
"""

__version__ = "0.1.0"
