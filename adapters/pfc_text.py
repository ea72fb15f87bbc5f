"""The ``pfc-text`` export target: sgim's PFC-style text lists of the model, nothing to run.

``write_deck(run, folder, model=model)`` writes ``balls.txt`` and ``contacts.txt`` of the sgim model the run was
made from (sgim.model.SphereModel.save_text: id, centre, radius and colour per ball; both ids, the bonded flag and
the cutting discontinuity per touching pair). It
needs the model itself (registry: needs_model): a run.npz carries no model.
"""
from __future__ import annotations

from pathlib import Path


def write_deck(run, folder, variant=None, *, model):
    """The registry's writer (adapters/registry.py): the model's balls.txt and contacts.txt in `folder`."""
    folder = Path(folder)
    model.save_text(folder / "balls.txt", folder / "contacts.txt")
    return {}


__all__ = ["write_deck"]
