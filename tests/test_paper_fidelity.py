"""docs/paper_fidelity.md stays true to the paper presets: every `setting = value` of its Ours column is what
``paper-llff`` and ``paper-360`` hold, and every setting on which they differ from the defaults is in it."""

from __future__ import annotations

import ast
import re
from dataclasses import fields
from pathlib import Path

import pytest

from gt2gs_blender.core.transfer.config import SETTINGS, TransferConfig
from gt2gs_blender.core.transfer.presets import PRESETS

TABLE = Path(__file__).resolve().parents[1] / "docs" / "paper_fidelity.md"
PAPER_PRESETS = ("paper-llff", "paper-360")
OURS = 3
"""The Ours column of every table (setting, paper, code, ours, why)."""
ASSIGNMENT = re.compile(r"`(\w+) = ([^`]+)`")


def ours_values() -> dict[str, tuple]:
    """Setting -> (paper-llff's value, paper-360's value), from the Ours column of every table row."""
    values: dict[str, tuple] = {}
    for line in TABLE.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") else []
        if len(cells) != 5 or set(cells[0]) <= {"-"} or cells[0] == "Setting":
            continue
        for name, text in ASSIGNMENT.findall(cells[OURS]):
            shown = [ast.literal_eval(part.strip()) for part in text.split(" / ")]
            assert name not in values, f"{name} is in the table twice"
            values[name] = (shown[0], shown[-1])
    return values


def test_the_table_parses_and_names_real_settings():
    values = ours_values()
    assert len(values) >= 25
    assert set(values) <= set(SETTINGS), set(values) - set(SETTINGS)


@pytest.mark.parametrize("index, name", enumerate(PAPER_PRESETS))
def test_the_ours_column_is_what_the_paper_presets_hold(index, name):
    wrong = {
        setting: (shown[index], getattr(PRESETS[name], setting))
        for setting, shown in ours_values().items()
        if shown[index] != getattr(PRESETS[name], setting)
    }
    assert not wrong, f"docs/paper_fidelity.md says (table, {name}): {wrong}"


def test_every_setting_a_paper_preset_changes_is_in_the_table():
    defaults = TransferConfig()
    changed = {
        f.name
        for f in fields(TransferConfig)
        for name in PAPER_PRESETS
        if getattr(PRESETS[name], f.name) != getattr(defaults, f.name)
    }
    missing = changed - set(ours_values())
    assert not missing, f"paper presets change {sorted(missing)}: add them to docs/paper_fidelity.md"
