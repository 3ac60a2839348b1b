"""One `medial template` run with default options, as the scripts that check templates make it.

Imported by `rotations.py` and `ventricles.py` (Python puts a script's own folder on its path).
Standard library only.
"""

import json
import os
import subprocess
import sys
import time


def own_file(path):
    """`path`, after refusing one that is a symbolic link or not a regular file: a script
    writes only the files of its output folder, never through a link to somewhere else."""
    if os.path.islink(path) or (os.path.exists(path) and not os.path.isfile(path)):
        sys.exit(f"error: {path} is a link or not a regular file; refusing to write it")
    return path


def build(medial, shape, out, name):
    """`medial template SHAPE --out OUT/NAME.vtk -q`: its exit code, seconds, figures (the JSON
    it wrote, {} when none) and output (stdout then stderr). A stale JSON of the same name is
    removed first, so that a failed run shows no figures."""
    template = os.path.join(out, f"{name}.vtk")
    figures_path = os.path.join(out, f"{name}.json")
    if os.path.exists(own_file(figures_path)):
        os.remove(figures_path)
    own_file(template)
    start = time.time()
    run = subprocess.run(
        [medial, "template", shape, "--out", template, "-q"], capture_output=True, text=True
    )
    seconds = time.time() - start
    figures = {}
    if os.path.exists(figures_path):
        with open(figures_path) as f:
            figures = json.load(f)
    return run.returncode, seconds, figures, run.stdout + run.stderr
