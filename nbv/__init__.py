"""The ``nbv`` command line (``nbv.cli``; ``python -m nbv``).

Importing it first makes this process, and the worker processes it starts, import our packages from the folder
``nbv`` was installed in rather than from a working folder or ``PYTHONPATH`` entry holding packages of the same
names (``nbv/import_path.py``).
"""

from nbv.import_path import prefer_installed_packages

prefer_installed_packages()
