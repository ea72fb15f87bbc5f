"""docs/scenes.md, the scene-key reference, is the fresh rendering of what the readers allow and read
(cases/make/scene_docs.py); every key the readers allow, in the synthetic scenes and in the case scenes, is
documented with a unit and a meaning; the defaults in the document are the ones the reader was recorded using."""
import inspect
import re
import tempfile

import pytest

from cases.make import scene_docs as M
from dda.generate import GENERATORS
from dda.scene import generator_parameters
from dda.scenedoc import DDA_KEYS, GENERATOR_PARAMS, record_dda
from sgim.scenedoc import NODEFAULT, SGIM_KEYS, Record, key_rows, record_sgim, show

# Two case scenes are left out for time: they add no table or key (dda_falling_polyhedra.toml is one [[generate]]
# of 1500 blocks; core_sample.toml a sieve packing filling a mesh, as the synthetic random_sieve and random_radius).
SLOW_CASES = {"dda_falling_polyhedra.toml", "core_sample.toml"}


@pytest.fixture(scope="module")
def synthetic():
    return M.record()


@pytest.fixture(scope="module")
def cases():
    sgim_files, dda_files = M.case_scenes()
    rs, rd = Record(), Record()
    with tempfile.TemporaryDirectory() as folder:
        record_sgim(rs, folder, [f for f in sgim_files if f.name not in SLOW_CASES], synthetic=False)
        record_dda(rd, folder, [f for f in dda_files if f.name not in SLOW_CASES], synthetic=False)
    return rs, rd


def test_document_is_fresh(synthetic):
    text = M.render(synthetic)
    assert M.DOC.read_text(encoding="utf-8") == text, f"docs/scenes.md is stale: run {M.COMMAND}"
    assert M.COMMAND in text.split("\n\n")[1]


def test_every_allowed_key_is_documented(synthetic, cases):
    for rec, meta, case_rec in zip(synthetic, (SGIM_KEYS, DDA_KEYS), cases):
        allowed = rec.allowed()
        assert len(allowed) > 60 and case_rec.scenes > 10
        assert case_rec.allowed() <= allowed, sorted(case_rec.allowed() - allowed)  # the synthetic scenes reach all
        assert set(case_rec.keys) <= set(rec.keys), sorted(set(case_rec.keys) - set(rec.keys))
        for k in allowed:
            assert k in meta, f"{k}: no unit and meaning"
            assert meta[k]["meaning"].strip(), k
            assert "unit" in meta[k], k
        assert set(meta) <= allowed, sorted(set(meta) - allowed)  # nothing documented that the reader refuses
        rows = key_rows(rec, meta)
        assert set(rows) == allowed
        for k, (typ, default, rng, unit, meaning) in rows.items():
            assert "?" not in typ and not default.startswith("VARIES"), (k, typ, default)


def test_units_agree_with_the_reader(synthetic):
    """Where the reader names a unit (its range messages), the document's unit is it."""
    for rec, meta in zip(synthetic, (SGIM_KEYS, DDA_KEYS)):
        for k, e in rec.keys.items():
            for u in e["units"]:
                assert u in [x.strip() for x in meta[k]["unit"].split(",")], (k, u, meta[k]["unit"])


def _doc_rows(text, section):
    """{(table title, key): cells} of a section of docs/scenes.md."""
    body = text.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    rows, title = {}, None
    for line in body.splitlines():
        if line.startswith("### "):
            title = line[4:]
        elif line.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            rows[(title, cells[0].strip("`").split(" (table")[0])] = cells
    return rows


def test_defaults_are_the_readers(synthetic, cases):
    """Every key read with one default, in the synthetic and the case scenes alike, shows it (unless its meaning
    table replaces a scene-dependent default with words); required keys say so."""
    from sgim.scenedoc import table_title

    text = M.DOC.read_text(encoding="utf-8")
    checked = 0
    for rec, case_rec, meta, section in zip(synthetic, cases, (SGIM_KEYS, DDA_KEYS), ("sgim scenes", "DDA scenes")):
        rows = _doc_rows(text, section)
        for k, e in rec.keys.items():
            if k not in rec.allowed() or "default" in meta[k]:
                continue
            table, _, leaf = k.rpartition(".")
            cells = rows[(table_title(table), leaf)]
            defaults = [d for d in e["defaults"] if d not in (NODEFAULT, '""')]
            if case_rec.keys.get(k):
                defaults_cases = [d for d in case_rec.keys[k]["defaults"] if d not in (NODEFAULT, '""')]
                assert set(defaults_cases) <= set(defaults), (k, defaults_cases, defaults)
            if defaults:
                assert len(defaults) == 1, (k, defaults)
                assert cells[2].startswith("empty" if defaults[0] == "{}" else defaults[0]), (k, cells[2], defaults)
                checked += 1
            if rec.required.get(k) == {True}:
                assert cells[2] == "required", (k, cells[2])
    assert checked > 50
    # spot checks against the reader's code (what a user relies on most)
    rows = _doc_rows(text, "DDA scenes")
    assert rows[("[simulation]", "safety")][2] == "0.5" and rows[("[simulation]", "duration")][2] == "required"
    assert rows[("[[material]]", "density")][2:5] == ["2600", ">= 1e-20, <= 1e+40", "kg/m3"]
    rows = _doc_rows(text, "sgim scenes")
    assert rows[("[bonds]", "tolerance")][2] == "0.001" and rows[("[domain]", "min")][2] == "required"


def test_generator_parameters(synthetic):
    """Each [[generate]] kind has a section listing every parameter of its signature with its default."""
    text = M.DOC.read_text(encoding="utf-8")
    for kind, fn in GENERATORS.items():
        section = text.split(f'### [[generate]] kind = "{kind}"\n', 1)[1].split("\n### ", 1)[0]
        params = {p: s for p, s in inspect.signature(fn).parameters.items()
                  if p in generator_parameters(fn)}  # the run's progress callback is no scene key
        assert set(GENERATOR_PARAMS[kind]) == set(params), kind
        for p, s in params.items():
            assert GENERATOR_PARAMS[kind][p]["meaning"], (kind, p)
            assert f"| `{p}` | {show(s.default)} |" in section, (kind, p)
