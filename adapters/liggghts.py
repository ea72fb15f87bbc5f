"""LIGGGHTS-PUBLIC: decks and runner for bonded-sphere runs (adapters.spec.SphereRun), the registry's
``liggghts`` target (adapters/registry.py).

``write_deck(run, folder, variant="bonds")`` writes ``data`` + ``in`` into `folder` (the caller saves
``run.npz`` beside them) and returns the extra deck.json keys; ``run_deck(folder, out, np=1, timeout=None,
progress=None)`` runs the deck and returns the RunResult it saved into `out`; ``check_deck(folder)`` reads the
deck back before a run.

By role:

- adapters/liggghts_deck.py: the deck (atom types, load groups, the box, the variants bonds / sjkr / clumps,
  what LIGGGHTS-PUBLIC cannot do exactly);
- adapters/liggghts_joints.py: spheres.liggghts_joints = "open" (no contact across a joint);
- adapters/liggghts_walls.py: run.extra joint_walls (the fixed side of a joint as a mesh wall; geometry in
  adapters/joint_walls.py);
- adapters/liggghts_run.py: the runner (bond breakage between chunks, results) and the deck read back;
- adapters/_liggghts_io.py: the data file, the dump reader and the engine driver.

Run by hand (no bond breakage, dumps every record): ``cd DECK && liggghts -in in``.
"""
from __future__ import annotations

from pathlib import Path

from sgim.readback import BadFile

from .liggghts_deck import (MAX_LOAD_GROUPS, RUNNER_FIELDS, VARIANTS, approximations, atom_types, clump_molecules,
                            clump_prescribed, cohesion_matrix, components, deck_box, load_groups, write_deck)
from .liggghts_joints import joint_closure, joint_exclusions, open_joint_notes, open_joint_problem, open_joints
from .liggghts_run import check_data, deck_variant, run_deck
from .liggghts_walls import wall_planes
from .spec import SphereRun


def check_deck(deck):
    """The registry's deck reader: the deck's run.npz read back, and the header of its data file checked against it
    (check_data, for the deck's variant) before LIGGGHTS starts; returns the SphereRun."""
    run = SphereRun.load(Path(deck) / "run.npz")
    check_data(Path(deck) / "data", run, deck_variant(deck))
    for k in range(1, len(wall_planes(run)) + 1):  # run.extra joint_walls: the walls' STL files
        if not (Path(deck) / f"wall_{k}.stl").is_file():
            raise BadFile(Path(deck) / f"wall_{k}.stl", "missing: the deck's joint wall (run.extra "
                          "joint_walls), written by `adapters export`")
    return run


__all__ = ["write_deck", "run_deck", "check_deck", "check_data", "deck_variant", "VARIANTS", "RUNNER_FIELDS",
           "atom_types", "components", "clump_molecules", "cohesion_matrix", "approximations", "clump_prescribed",
           "deck_box", "load_groups", "MAX_LOAD_GROUPS", "open_joints", "open_joint_problem", "joint_exclusions",
           "open_joint_notes", "joint_closure"]
