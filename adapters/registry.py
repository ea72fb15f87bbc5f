"""The engines and formats of the adapters, one Target entry each: what `adapters export --to` writes and
`adapters run` runs.

As meshio keeps its formats, every target is a module of its own holding its writer, runner and reader:

==============  ==========  ==================  ===================================================================
target          --to        module              deck
==============  ==========  ==================  ===================================================================
yade            yade        adapters.yade       script.py + yade.json + run.npz (JCFpm bonded spheres)
yade-polyhedra  yade        adapters.yade_poly  script.py + poly.json + blocks.npz (a DDA block scene)
liggghts        liggghts    adapters.liggghts   data + in + run.npz (variants bonds, sjkr, clumps)
pfc-text        pfc-text    adapters.pfc_text   balls.txt + contacts.txt (no runner)
vtu             vtu         adapters.vtu        spheres.vtu + bonds.vtu (no runner)
dda             (none)      adapters.inhouse    runs a sphere deck's run.npz in-house (``adapters run --in-house``)
==============  ==========  ==================  ===================================================================

The roles, functions of the target's module named by the entry:

- writer ``(run, folder, variant)`` -> dict of extra deck.json keys, for a SphereRun (``source = "spheres"``);
  for a block scene (``source = "blocks"``) ``(scene_path, folder, prepared)`` with ``prepare(scene_path,
  overrides, max_steps)`` run first, before the deck folder is made (it refuses an overlong run);
- runner ``(deck, out, np=1, timeout=None, progress=None)`` -> the RunResult it saved into `out`;
- reader ``(deck)``: reads back and checks every file of the deck the runner will read, before the engine starts;
  returns the deck's SphereRun (None for a block deck).

adapters/deck.py, adapters/cli.py and the package top look targets up here; nothing else dispatches on a
target's name. A new engine: its module with these functions, and one Target line in TARGETS.

The modules are named, not imported: each is imported when its target is first used, so that `adapters
--help` lists the targets without loading numpy or any engine module.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class Target:
    """One engine or format: its names, its module's writer / runner / reader, and what it can express."""

    name: str                    # deck.json "engine"; `adapters run` finds the runner by it
    to: str | None               # the `adapters export --to` name (None: nothing to export)
    module: str                  # the module holding the functions below
    summary: str                 # what the deck holds (one line)
    source: str = "spheres"      # what it exports: "spheres" (a SphereRun) or "blocks" (a DDA block scene)
    writer: str | None = None    # function names in `module` (None: the target has no such role)
    runner: str | None = None
    reader: str | None = None
    prepare: str | None = None   # blocks: checks and settings before the deck folder is made
    variants: tuple = ()         # --variant values it takes
    default_variant: str | None = None  # the variant a deck gets without --variant
    checks_variant: bool = False  # the runner reads deck.json's variant: read_deck checks it
    options: tuple = ()          # export overrides only this target takes (e.g. liggghts_joints)
    needs_model: bool = False    # writes from the sgim model (a run.npz has none)
    saves_run: bool = False      # the deck holds run.npz (the SphereRun its runner reads)
    deck_files: tuple = ()       # files a complete deck holds (checked before a run)

    @property
    def runnable(self):
        return self.runner is not None

    def function(self, role):
        """The function of `role` ("writer", "runner", "reader", "prepare") in the target's module."""
        name = getattr(self, role)
        if name is None:
            raise LookupError(f"{self.name} has no {role}")
        return getattr(importlib.import_module(self.module), name)

    def write(self, *args, **kw):
        return self.function("writer")(*args, **kw)

    def run(self, *args, **kw):
        return self.function("runner")(*args, **kw)

    def read(self, *args, **kw):
        return self.function("reader")(*args, **kw)


TARGETS = (
    Target("yade", "yade", "adapters.yade", "script.py + yade.json + run.npz (JCFpm bonded spheres)",
           writer="export_deck", runner="run_deck", reader="check_deck", variants=("jcfpm",), saves_run=True,
           options=("joint_walls",), deck_files=("run.npz", "script.py", "yade.json")),
    Target("yade-polyhedra", "yade", "adapters.yade_poly", "a YADE Polyhedra deck of a DDA block scene",
           source="blocks", writer="export_deck", runner="run_polyhedra_deck", reader="check_deck",
           prepare="prepare_deck", deck_files=("blocks.npz", "poly.json", "script.py")),
    Target("liggghts", "liggghts", "adapters.liggghts", "data + in + run.npz (variant: bonds, sjkr, clumps)",
           writer="write_deck", runner="run_deck", reader="check_deck", variants=("bonds", "sjkr", "clumps"),
           default_variant="bonds", checks_variant=True, options=("liggghts_joints", "liggghts_joint_walls", "joint_walls"),
           saves_run=True,
           deck_files=("run.npz", "data", "in")),
    Target("pfc-text", "pfc-text", "adapters.pfc_text", "balls.txt + contacts.txt (sgim's PFC-style text lists)",
           writer="write_deck", needs_model=True),
    Target("vtu", "vtu", "adapters.vtu", "spheres.vtu + bonds.vtu (points: radius, colour, fixed, bond count; "
           "lines)", writer="write_deck"),
    Target("dda", None, "adapters.inhouse", "the in-house engine (dda.spheres) on a sphere deck's run.npz",
           runner="run_deck"),
)


def export_names():
    """The `adapters export --to` names, in order (a name may stand for one target per source kind)."""
    return tuple(dict.fromkeys(t.to for t in TARGETS if t.to is not None))


def runnable_names():
    """The engines of the decks `adapters run` runs (deck.json "engine")."""
    return tuple(t.name for t in TARGETS if t.runnable and t.writer is not None)


def for_export(to, source="spheres"):
    """The target that `--to to` writes for a source of kind `source` ("spheres" or "blocks"); None when there
    is none (an unknown name, or a name that does not take that kind of source)."""
    return next((t for t in TARGETS if t.to == to and t.source == source), None)


def export_variants(to):
    """The --variant values of the sphere target `to` (() for none or an unknown name)."""
    t = for_export(to)
    return t.variants if t is not None else ()


def target(name):
    """The target of deck.json engine `name` (None when there is none)."""
    return next((t for t in TARGETS if t.name == name), None)


__all__ = ["Target", "TARGETS", "export_names", "runnable_names", "for_export", "export_variants", "target"]
