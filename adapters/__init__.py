"""Adapters: bonded-sphere models and block scenes as YADE and LIGGGHTS decks, their runs, one result format.

- spec.py: SphereRun, the engine-neutral description of a run (from a DDA scene with [spheres] or a model)
- deck.py: export to yade | liggghts | pfc-text | vtu; run a deck with its engine
- yade.py / yade_script.py: JCFpm bonded spheres with the model's exact per-pair rule and smooth joints
- yade_poly.py / yade_poly_script.py: YADE Polyhedra decks of DDA block scenes
- liggghts.py: data + in decks (harmonic bonds, sjkr cohesion, rigid clumps) and the chunked runner
- inhouse.py: the same run with the in-house engine (dda.spheres)
- process.py: engine subprocesses (time limit, error line); result.py: RunResult
- cli.py: ``adapters export`` and ``adapters run``
"""
