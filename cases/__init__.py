"""Case scenes (cases/scenes/), the study runner and cross-validation (cases/lib/), benchmarks (cases/bench/) and
the generators of the scene files (cases/make/)."""
from pathlib import Path

SCENES = Path(__file__).resolve().parent / "scenes"  # the scene files: *.toml, crossval/, studies/, meshes/
