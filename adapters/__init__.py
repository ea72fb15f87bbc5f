"""Adapters: bonded-sphere models and block scenes as YADE and LIGGGHTS decks, their runs, one result format.

- spec.py: SphereRun, the engine-neutral description of a run (from a DDA scene with [spheres] or a model)
- registry.py: the targets (engines and formats), one entry each naming its module's writer, runner and reader
- deck.py: export a source for a target (yade | liggghts | pfc-text | vtu); run a deck with its target's runner
- the targets, one module each: yade.py (+ yade_script.py, run by YADE: JCFpm bonded spheres with the model's
  exact per-pair rule and smooth joints), yade_poly.py (+ yade_poly_script.py: YADE Polyhedra decks of DDA block
  scenes), liggghts.py (data + in decks: harmonic bonds, sjkr cohesion, rigid clumps, and the chunked runner;
  by role in liggghts_deck.py, liggghts_joints.py, liggghts_run.py, _liggghts_io.py), pfc_text.py, vtu.py,
  inhouse.py (the same run with the in-house engine, dda.spheres)
- process.py: engine subprocesses (time limit, error line); result.py: RunResult; frames.py: ParaView files
- cli.py: ``adapters export`` and ``adapters run``

The Python API (docs/api.md)::

    import adapters
    info = adapters.export("cases/scenes/crossval/column.toml", "yade", "deck")  # deck.json as a dict
    res = adapters.run("deck")       # a RunResult (time, positions, bonds intact, ...), saved in deck/result
    res = adapters.run_inhouse(adapters.SphereRun.load("deck/run.npz"))   # the same run, in-house
    same = adapters.load_result("deck/result")

Names are imported from their modules when first used: ``import adapters`` stays light.
"""

__all__ = ["export", "run", "run_inhouse", "load_result", "SphereRun", "RunResult", "DeckError"]
_WHERE = {"export": "deck", "run": "deck", "DeckError": "deck", "run_inhouse": "inhouse", "SphereRun": "spec",
          "RunResult": "result"}


def load_result(folder):
    """The RunResult saved in a result folder (result.npz and result.json) by ``adapters run``."""
    from .result import RunResult  # lazy: see the module docstring

    return RunResult.load(folder)


def __getattr__(name):
    if name in _WHERE:
        import importlib  # lazy, as the names

        return getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'adapters' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
