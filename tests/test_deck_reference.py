"""docs/deck-reference.md is generated from the parser's schema (nurbsdem.io.deck_schema.SCHEMA) and
the descriptions of nurbsdem.io.deck_reference: every key the parser accepts is documented,
no description names a key the parser lacks, and the file in docs/ is the rendered text."""
from __future__ import annotations

import copy

import pytest

from nurbsdem.io import deck_reference as ref
from nurbsdem.io.deck_schema import F1, SCHEMA, EntrySpec


def test_every_schema_key_has_a_description():
    assert ref.undocumented() == [], (
        "describe these in nurbsdem/io/deck_reference.py (KEYS / ENTRIES), then run "
        "python -m nurbsdem.io.deck_reference")


def test_no_description_names_a_key_the_schema_lacks():
    assert ref.unknown() == []


def test_the_checks_see_a_key_added_to_or_removed_from_the_schema():
    schema = copy.deepcopy(SCHEMA)
    spec = schema["Contact"]["Interface"]
    keys = dict(spec.keys)
    keys["Cohesion"] = F1
    del keys["Friction"]
    schema["Contact"]["Interface"] = EntrySpec(spec.numbered, keys, spec.head)
    schema["Output"]["Logs"] = EntrySpec(False, {"Every": F1})
    assert ref.undocumented(schema) == ["Output/Logs", "Contact/Interface/Cohesion",
                                        "Output/Logs/Every"]
    assert ref.unknown(schema) == ["Contact/Interface/Friction"]
    with pytest.raises(ValueError, match="Cohesion"):
        ref.render(schema)


def test_every_key_and_default_appears_in_the_rendered_reference():
    text = ref.render()
    for (block, entry, key), doc in ref.KEYS.items():
        section = text.split(f"### {entry}\n")[1].split("\n### ")[0]
        label = "(after the keyword)" if key == ref.HEAD else f"`{key}`"
        row = next(ln for ln in section.splitlines() if ln.startswith(f"| {label} |"))
        assert f"| {doc.default.replace('|', chr(92) + '|')} |" in row, (block, entry, key)


def test_docs_deck_reference_is_the_rendered_text():
    assert ref.REFERENCE_PATH.is_file(), "run python -m nurbsdem.io.deck_reference"
    assert ref.REFERENCE_PATH.read_text(encoding="utf-8") == ref.render(), (
        "docs/deck-reference.md is stale: run python -m nurbsdem.io.deck_reference")
