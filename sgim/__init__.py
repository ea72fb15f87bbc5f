"""SGIM: sphere generator for irregular geological models.

Packs spheres in a domain, excavates them with triangulated surfaces, cuts them with discontinuities (colours
and membership) and builds the bond list. The Python API (docs/api.md)::

    import sgim
    model = sgim.build("cases/scenes/open_pit.toml")  # a SphereModel: centers, radii, colour, bonds, bonded, ...
    model.save("model.npz")
    same = sgim.load("model.npz")
    scene = sgim.load_scene("cases/scenes/open_pit.toml")  # the validated Scene (SceneError on bad input)

The functions import the package's modules when first called: ``import sgim`` stays light. What every package
of the project shares (SceneError, CliError, the command-line conventions, atomic writers) is sgim/common.py; the
validating reader of every scene-like TOML file is sgim/reader.py.
"""
# The functions below import the build, the scene reader and the model when first called: `import sgim` stays light
from .kernel_cache import configure as _configure_kernel_cache

_configure_kernel_cache()  # before any kernel module is imported (sgim/kernel_cache.py)

from .common import SceneError, __version__  # noqa: E402  (standard library only: `import sgim` stays light)

__all__ = ["build", "load", "load_scene", "SceneError"]


def load_scene(scene):
    """The validated scene of a TOML file (a path), of a dict holding the TOML's tables, or `scene` itself when
    it is already a Scene. Bad input raises SceneError (file, key, value and what is wrong)."""
    from .scene import Scene, scene_from_dict
    from .scene import load_scene as _load

    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, dict):
        return scene_from_dict(scene, f"{scene.get('name', 'scene')}.toml")
    return _load(scene)


def build(scene, progress=None, max_spheres=None):
    """Build the bonded sphere model of `scene` (a TOML path, a dict of the TOML's tables, or a Scene) and return
    its SphereModel (sgim/model.py). `progress(line)` receives the stages' progress lines; `max_spheres`
    overrides the scene's [limits] max_spheres (sgim/limits.py). Nothing is written: ``model.save(path)``,
    ``model.save_vtu(path)`` write the files ``sgim build`` writes."""
    from .builder import build_model

    return build_model(load_scene(scene), progress=progress, max_spheres=max_spheres)


def load(path):
    """The SphereModel of a model.npz written by ``sgim build`` (or ``model.save``), validated: a file that is not
    a readable model raises sgim.readback.BadFile naming the file and what is wrong."""
    from .model import SphereModel

    return SphereModel.load(path)

