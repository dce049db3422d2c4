"""occmap's one C extension, the geometry functions' single-element path (its source says why);
everything else about the package is in pyproject.toml. NumPy's headers: it allocates the arrays
it returns."""

import numpy
from setuptools import Extension, setup

setup(ext_modules=[Extension("occmap.geometry._single", ["src/occmap/geometry/_single.c"],
                             include_dirs=[numpy.get_include()])])
