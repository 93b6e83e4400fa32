"""Executes a notebook top to bottom in a fresh kernel, as a reader would; any cell's error fails.

    python tests/run_notebook.py examples/design_study.ipynb
"""

import sys

import nbformat
from nbclient import NotebookClient

notebook = nbformat.read(sys.argv[1], as_version=4)
NotebookClient(notebook, timeout=600, kernel_name="python3").execute()
print(f"{sys.argv[1]}: every cell ran")
