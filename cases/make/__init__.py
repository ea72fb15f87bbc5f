"""Generator scripts of the scene files in cases/scenes/ and docs/scenes.md, and the Python API example."""
