"""Make organ.msh next to this file (needs gmsh: pip install gmsh); options: --size, --order, --scale.

    python examples/organ/make_organ.py            # writes examples/organ/organ.msh
    python examples/organ/make_organ.py liver.msh --scale 2.2 --size 0.006 --order 2

The geometry, groups and options are tensormass.apps.organ_mesh's (see there).
"""
import sys
from pathlib import Path

from tensormass.apps.organ_mesh import main, make  # noqa: F401  (make: for scripts that import this file)

if __name__ == "__main__":
    sys.exit(main(default_path=str(Path(__file__).with_name("organ.msh"))))
