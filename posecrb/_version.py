"""The version of posecrb: the ground floor every layer may import (it imports nothing).

``posecrb.__version__``, the ``User-Agent`` of downloads, ``posecrb --version`` and the run records
read it from here, never from the package root (which imports upwards, into the library).
pyproject.toml's ``version`` must say the same (tests/package/test_packaging.py checks it).
"""

__version__ = "0.2.0"
